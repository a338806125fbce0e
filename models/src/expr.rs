//! Plain expression trees and the paper's notation.
//!
//! [`Expr`] is the naive form of a switching function: a tree evaluated by
//! recursion. It is the reference the compiled evaluator is tested against,
//! and the form the paper's equations are read into ([`Expr::parse`]:
//! `(X4) * (-Y2) * (((X1)*(-X2)) + (-X3))`, with `·` accepted for AND),
//! failing with an [`ExprError`] that names the character and its place.

use std::collections::BTreeSet;

use crate::signal::Signal;

/// Why a text is not an expression in the paper's notation; positions are
/// 1-based character offsets into the text.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ExprError {
    /// A character where none of its kind may stand.
    #[error("unexpected '{found}' at character {at}")]
    Unexpected {
        /// The character.
        found: char,
        /// Its position.
        at: usize,
    },
    /// The text ends where an operand is wanted.
    #[error("unexpected end of expression")]
    UnexpectedEnd,
    /// A parenthesis left open by another character.
    #[error("expected ')' at character {at}, found '{found}'")]
    Unclosed {
        /// The character instead of `)`.
        found: char,
        /// Its position.
        at: usize,
    },
    /// A parenthesis still open at the end of the text.
    #[error("expected ')' at the end")]
    UnclosedAtEnd,
    /// A comparison with a character where its right-hand side is wanted.
    #[error("expected a number or a tag after '{op}' at character {at}, found '{found}'")]
    NoOperand {
        /// The comparison operator (`>`, `==`, ...).
        op: &'static str,
        /// The character instead of the operand.
        found: char,
        /// Its position.
        at: usize,
    },
    /// A comparison at the end of the text, without its right-hand side.
    #[error("expected a number or a tag after '{op}'")]
    NoOperandAtEnd {
        /// The comparison operator (`>`, `==`, ...).
        op: &'static str,
    },
    /// A right-hand side with a minus sign that is not a number (`-x`).
    #[error("'{text}' after '{op}' is not a number")]
    NotANumber {
        /// The right-hand side as written.
        text: String,
        /// The comparison operator (`>`, `==`, ...).
        op: &'static str,
    },
}

/// A boolean expression tree.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Expr {
    /// `TRUE` / `FALSE`.
    Const(bool),
    /// A signal, negated when the flag is set.
    Lit(Signal, bool),
    /// Negation of a sub-expression.
    Not(Box<Expr>),
    /// Conjunction.
    And(Vec<Expr>),
    /// Disjunction.
    Or(Vec<Expr>),
}

impl Expr {
    /// Evaluates the tree.
    pub fn eval(&self, value: &impl Fn(&Signal) -> bool) -> bool {
        match self {
            Expr::Const(v) => *v,
            Expr::Lit(s, negated) => value(s) != *negated,
            Expr::Not(e) => !e.eval(value),
            Expr::And(es) => es.iter().all(|e| e.eval(value)),
            Expr::Or(es) => es.iter().any(|e| e.eval(value)),
        }
    }

    /// Every signal the tree reads.
    pub fn signals(&self) -> BTreeSet<Signal> {
        let mut out = BTreeSet::new();
        self.collect(&mut out);
        out
    }

    fn collect(&self, out: &mut BTreeSet<Signal>) {
        match self {
            Expr::Const(_) => {}
            Expr::Lit(s, _) => {
                out.insert(s.clone());
            }
            Expr::Not(e) => e.collect(out),
            Expr::And(es) | Expr::Or(es) => es.iter().for_each(|e| e.collect(out)),
        }
    }

    /// The same tree with nested same-operator nodes merged and children
    /// sorted: two expressions that differ only in grouping and order of
    /// AND/OR terms compare equal after this.
    #[must_use]
    pub fn canonical(&self) -> Expr {
        match self {
            Expr::Not(e) => match e.canonical() {
                Expr::Lit(s, n) => Expr::Lit(s, !n),
                Expr::Const(v) => Expr::Const(!v),
                other => Expr::Not(Box::new(other)),
            },
            Expr::And(es) | Expr::Or(es) => {
                let is_and = matches!(self, Expr::And(_));
                let mut flat = Vec::new();
                for e in es.iter().map(Expr::canonical) {
                    match e {
                        Expr::And(inner) if is_and => flat.extend(inner),
                        Expr::Or(inner) if !is_and => flat.extend(inner),
                        other => flat.push(other),
                    }
                }
                flat.sort();
                if flat.len() == 1 {
                    return flat.remove(0);
                }
                if is_and {
                    Expr::And(flat)
                } else {
                    Expr::Or(flat)
                }
            }
            other => other.clone(),
        }
    }

    /// Reads the paper's notation: `+` OR, `*` or `·` AND, `-` NOT,
    /// parentheses, and signal names (any run of letters, digits, `.`, `_`,
    /// `%`). A name followed by a comparison (`TEMP > 80.5`, `MODE == 3`,
    /// `P1 >= P2`) is one contact, named `LHS OP RHS` (see
    /// [`crate::value::Comparison`]).
    ///
    /// # Errors
    /// [`ExprError`] with the character offset of the problem.
    pub fn parse(text: &str) -> Result<Expr, ExprError> {
        let tokens: Vec<(usize, char)> = text.chars().enumerate().collect();
        let mut p = Parser { tokens, at: 0 };
        let e = p.or()?;
        match p.peek() {
            None => Ok(e),
            Some((i, c)) => Err(ExprError::Unexpected {
                found: c,
                at: i + 1,
            }),
        }
    }
}

/// The expression as [`Expr::parse`] reads it: `+` or, `*` and, `-` not,
/// parentheses where an `or` is inside an `and` or a `not`.
impl std::fmt::Display for Expr {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let inner = |e: &Expr, f: &mut std::fmt::Formatter<'_>| match e {
            Expr::Or(items) if items.len() > 1 => write!(f, "({e})"),
            Expr::And(items) if items.len() > 1 => write!(f, "({e})"),
            _ => write!(f, "{e}"),
        };
        match self {
            Expr::Const(true) => f.write_str("TRUE"),
            Expr::Const(false) => f.write_str("FALSE"),
            Expr::Lit(s, false) => write!(f, "{s}"),
            Expr::Lit(s, true) => write!(f, "-{s}"),
            Expr::Not(e) => {
                f.write_str("-")?;
                inner(e, f)
            }
            Expr::And(items) => {
                for (i, e) in items.iter().enumerate() {
                    if i > 0 {
                        f.write_str(" * ")?;
                    }
                    match e {
                        Expr::Or(o) if o.len() > 1 => write!(f, "({e})")?,
                        _ => write!(f, "{e}")?,
                    }
                }
                Ok(())
            }
            Expr::Or(items) => {
                for (i, e) in items.iter().enumerate() {
                    if i > 0 {
                        f.write_str(" + ")?;
                    }
                    write!(f, "{e}")?;
                }
                Ok(())
            }
        }
    }
}

struct Parser {
    tokens: Vec<(usize, char)>,
    at: usize,
}

impl Parser {
    /// The next character that is not white space.
    fn peek(&mut self) -> Option<(usize, char)> {
        while self
            .tokens
            .get(self.at)
            .is_some_and(|(_, c)| c.is_whitespace())
        {
            self.at += 1;
        }
        self.tokens.get(self.at).copied()
    }

    fn or(&mut self) -> Result<Expr, ExprError> {
        let mut terms = vec![self.and()?];
        while let Some((_, '+')) = self.peek() {
            self.at += 1;
            terms.push(self.and()?);
        }
        Ok(if terms.len() == 1 {
            terms.remove(0)
        } else {
            Expr::Or(terms)
        })
    }

    fn and(&mut self) -> Result<Expr, ExprError> {
        let mut terms = vec![self.unary()?];
        while let Some((_, '*' | '·')) = self.peek() {
            self.at += 1;
            terms.push(self.unary()?);
        }
        Ok(if terms.len() == 1 {
            terms.remove(0)
        } else {
            Expr::And(terms)
        })
    }

    fn unary(&mut self) -> Result<Expr, ExprError> {
        match self.peek() {
            Some((_, '-')) => {
                self.at += 1;
                Ok(match self.unary()? {
                    Expr::Lit(s, n) => Expr::Lit(s, !n),
                    other => Expr::Not(Box::new(other)),
                })
            }
            Some((_, '(')) => {
                self.at += 1;
                let e = self.or()?;
                match self.peek() {
                    Some((_, ')')) => {
                        self.at += 1;
                        Ok(e)
                    }
                    Some((i, c)) => Err(ExprError::Unclosed {
                        found: c,
                        at: i + 1,
                    }),
                    None => Err(ExprError::UnclosedAtEnd),
                }
            }
            Some((_, c)) if is_name(c) => {
                let mut name = String::new();
                while let Some(&(_, c)) = self.tokens.get(self.at).filter(|(_, c)| is_name(*c)) {
                    name.push(c);
                    self.at += 1;
                }
                if let Some(op) = self.comparison_operator() {
                    let rhs = self.operand(op)?;
                    return Ok(Expr::Lit(Signal::new(&format!("{name} {op} {rhs}")), false));
                }
                Ok(match name.to_ascii_uppercase().as_str() {
                    "TRUE" => Expr::Const(true),
                    "FALSE" => Expr::Const(false),
                    _ => Expr::Lit(Signal::new(&name), false),
                })
            }
            Some((i, c)) => Err(ExprError::Unexpected {
                found: c,
                at: i + 1,
            }),
            None => Err(ExprError::UnexpectedEnd),
        }
    }
}

impl Parser {
    /// A comparison operator after a name (`>`, `>=`, `<`, `<=`, `==`,
    /// `!=`), consumed.
    fn comparison_operator(&mut self) -> Option<&'static str> {
        let (_, first) = self.peek()?;
        let second = self.tokens.get(self.at + 1).map(|&(_, c)| c);
        let (op, len) = match (first, second) {
            ('>', Some('=')) => (">=", 2),
            ('<', Some('=')) => ("<=", 2),
            ('=', Some('=')) => ("==", 2),
            ('!', Some('=')) => ("!=", 2),
            ('>', _) => (">", 1),
            ('<', _) => ("<", 1),
            _ => return None,
        };
        self.at += len;
        Some(op)
    }

    /// The right-hand side of a comparison: a number (optionally negative)
    /// or a name.
    fn operand(&mut self, op: &'static str) -> Result<String, ExprError> {
        let mut text = String::new();
        if let Some((_, '-')) = self.peek() {
            self.at += 1;
            text.push('-');
        }
        while let Some(&(_, c)) = self.tokens.get(self.at).filter(|(_, c)| is_name(*c)) {
            text.push(c);
            self.at += 1;
        }
        if text.is_empty() || text == "-" {
            return Err(match self.peek() {
                Some((i, c)) => ExprError::NoOperand {
                    op,
                    found: c,
                    at: i + 1,
                },
                None => ExprError::NoOperandAtEnd { op },
            });
        }
        if text.starts_with('-') && text[1..].parse::<f64>().is_err() {
            return Err(ExprError::NotANumber { text, op });
        }
        Ok(text)
    }
}

fn is_name(c: char) -> bool {
    c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '%')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_papers_notation() {
        let e = Expr::parse("(X4) * (-Y2) * (((X1)*(-X2)) + (-X3)) · (-Y1)").unwrap();
        let v = |s: &Signal| matches!(s.name(), "X4" | "X1");
        assert!(e.eval(&v));
        assert_eq!(e.signals().len(), 6);
        assert_eq!(
            Expr::parse("-(a + b)").unwrap(),
            Expr::Not(Box::new(Expr::Or(vec![
                Expr::Lit(Signal::new("a"), false),
                Expr::Lit(Signal::new("b"), false)
            ])))
        );
        assert_eq!(
            Expr::parse("a + (b").unwrap_err().to_string(),
            "expected ')' at the end"
        );
        assert_eq!(
            Expr::parse("a b").unwrap_err().to_string(),
            "unexpected 'b' at character 3"
        );
    }

    #[test]
    fn it_prints_as_it_is_read() {
        for text in [
            "X4 * -Y2 * (X1 * -X2 + -X3) * -Y1",
            "-(a + b)",
            "%IX0.0.3 * -(%IX0.1.0 * S2.X)",
            "TEMP > 80.5 + TRUE",
        ] {
            let e = Expr::parse(text).unwrap();
            assert_eq!(e.to_string(), text);
            assert_eq!(Expr::parse(&e.to_string()).unwrap(), e);
        }
    }

    #[test]
    fn comparisons_are_contacts() {
        let e = Expr::parse("TEMP>80.5 * (MODE == 3 + P1>=P2) * -(LEVEL < -2)").unwrap();
        let names: Vec<String> = e.signals().iter().map(|s| s.to_string()).collect();
        assert_eq!(
            names,
            ["LEVEL < -2", "MODE == 3", "P1 >= P2", "TEMP > 80.5"]
        );
        assert_eq!(
            Expr::parse("TEMP > ").unwrap_err().to_string(),
            "expected a number or a tag after '>'"
        );
        assert_eq!(
            Expr::parse("TEMP > -x").unwrap_err().to_string(),
            "'-x' after '>' is not a number"
        );
    }

    #[test]
    fn canonical_ignores_grouping_and_order() {
        let a = Expr::parse("(a * b) * (c + d)").unwrap().canonical();
        let b = Expr::parse("(d + c) * b * a").unwrap().canonical();
        assert_eq!(a, b);
    }
}
