//! The neutral text of one Logix ladder rung (`XIC(a)[XIO(b),XIC(c)]OTE(d);`)
//! read into a tree of instructions and branches, each with its byte
//! offset in the text. What the instructions mean is `l5x/mod.rs`'s job;
//! this module only reads the text's shape.

/// How deep branches may nest inside one rung.
pub(super) const MAX_BRANCH_DEPTH: usize = 64;

/// An instruction as written: `TON(Timer1,?,?)`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct Ins {
    /// Byte offset of the mnemonic in the rung text.
    pub(super) at: usize,
    /// The mnemonic as written (`XIC`, `MyAoi`).
    pub(super) name: String,
    /// The operands, trimmed, with their byte offsets.
    pub(super) args: Vec<(usize, String)>,
    /// The whole instruction as written, for messages.
    pub(super) text: String,
}

/// One element of a rung: an instruction, or parallel branches.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum Element {
    Ins(Ins),
    /// `[ leg , leg , ... ]`, at the offset of its `[`.
    Branch(usize, Vec<Vec<Element>>),
}

/// Reads a rung's text.
///
/// # Errors
/// The byte offset and what is wrong: an unbalanced bracket or
/// parenthesis, a character that starts no instruction, a missing `;`,
/// branches nested deeper than [`MAX_BRANCH_DEPTH`].
pub(super) fn parse(text: &str) -> Result<Vec<Element>, (usize, String)> {
    let mut reader = Reader { text, pos: 0 };
    let elements = reader.sequence(0)?;
    reader.skip_space();
    match reader.peek() {
        Some(';') => {
            reader.pos += 1;
            reader.skip_space();
            match reader.peek() {
                None => Ok(elements),
                Some(c) => Err((reader.pos, format!("'{c}' after the rung's closing ';'"))),
            }
        }
        None => Err((reader.pos, "the rung text does not end with ';'".into())),
        Some(c @ (']' | ',')) => Err((reader.pos, format!("'{c}' outside any branch '['"))),
        Some(c) => Err((reader.pos, format!("unexpected '{c}'"))),
    }
}

struct Reader<'t> {
    text: &'t str,
    pos: usize,
}

impl Reader<'_> {
    fn peek(&self) -> Option<char> {
        self.text[self.pos..].chars().next()
    }

    fn skip_space(&mut self) {
        while let Some(c) = self.peek().filter(|c| c.is_whitespace()) {
            self.pos += c.len_utf8();
        }
    }

    /// Instructions and branches up to a `,`, `]`, `;` or the end.
    fn sequence(&mut self, depth: usize) -> Result<Vec<Element>, (usize, String)> {
        let mut out = Vec::new();
        loop {
            self.skip_space();
            match self.peek() {
                None | Some(',' | ']' | ';') => return Ok(out),
                Some('[') => {
                    let open = self.pos;
                    if depth >= MAX_BRANCH_DEPTH {
                        return Err((
                            open,
                            format!("branches nested deeper than {MAX_BRANCH_DEPTH}"),
                        ));
                    }
                    self.pos += 1;
                    let mut legs = vec![self.sequence(depth + 1)?];
                    loop {
                        match self.peek() {
                            Some(',') => {
                                self.pos += 1;
                                legs.push(self.sequence(depth + 1)?);
                            }
                            Some(']') => {
                                self.pos += 1;
                                break;
                            }
                            _ => return Err((open, "branch '[' is never closed with ']'".into())),
                        }
                    }
                    out.push(Element::Branch(open, legs));
                }
                Some(c) if c.is_ascii_alphabetic() || c == '_' => out.push(self.instruction()?),
                Some(c) => return Err((self.pos, format!("unexpected '{c}'"))),
            }
        }
    }

    /// `NAME(arg,arg,...)`: arguments split at commas outside parentheses,
    /// brackets and quotes.
    fn instruction(&mut self) -> Result<Element, (usize, String)> {
        let start = self.pos;
        while let Some(c) = self
            .peek()
            .filter(|c| c.is_ascii_alphanumeric() || *c == '_')
        {
            self.pos += c.len_utf8();
        }
        let name = self.text[start..self.pos].to_string();
        if self.peek() != Some('(') {
            return Err((
                start,
                format!("instruction '{name}' without its operands in parentheses"),
            ));
        }
        self.pos += 1;
        let mut args = Vec::new();
        let mut arg_start = self.pos;
        let mut nesting: Vec<char> = Vec::new();
        loop {
            let Some(c) = self.peek() else {
                return Err((start, format!("'{name}(' is never closed with ')'")));
            };
            let here = self.pos;
            self.pos += c.len_utf8();
            match c {
                '\'' | '"' => {
                    // A string literal: up to its closing quote.
                    match self.text[self.pos..].find(c) {
                        Some(n) => self.pos += n + 1,
                        None => return Err((here, format!("string {c}...{c} is never closed"))),
                    }
                }
                '(' | '[' => nesting.push(c),
                ')' | ']' => {
                    let open = if c == ')' { '(' } else { '[' };
                    match nesting.pop() {
                        Some(o) if o == open => {}
                        None if c == ')' => {
                            push_arg(&mut args, self.text, arg_start, here);
                            break;
                        }
                        _ => return Err((here, format!("unbalanced '{c}' in '{name}(...)'"))),
                    }
                }
                ',' if nesting.is_empty() => {
                    push_arg(&mut args, self.text, arg_start, here);
                    arg_start = self.pos;
                }
                _ => {}
            }
        }
        // `NOP()`: no operand at all.
        if args.len() == 1 && args[0].1.is_empty() {
            args.clear();
        }
        Ok(Element::Ins(Ins {
            at: start,
            name,
            args,
            text: self.text[start..self.pos].to_string(),
        }))
    }
}

fn push_arg(args: &mut Vec<(usize, String)>, text: &str, from: usize, to: usize) {
    let raw = &text[from..to];
    let lead = raw.len() - raw.trim_start().len();
    args.push((from + lead, raw.trim().to_string()));
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape(elements: &[Element]) -> String {
        elements
            .iter()
            .map(|e| match e {
                Element::Ins(i) => {
                    let args: Vec<&str> = i.args.iter().map(|(_, a)| a.as_str()).collect();
                    format!("{}@{}({})", i.name, i.at, args.join("|"))
                }
                Element::Branch(at, legs) => {
                    let legs: Vec<String> = legs.iter().map(|l| shape(l)).collect();
                    format!("[@{at} {}]", legs.join(" , "))
                }
            })
            .collect::<Vec<_>>()
            .join(" ")
    }

    #[test]
    fn instructions_branches_and_operands() {
        let r = parse("XIC(a)[XIO(b) ,XIC(c)[,XIO(d)]]CPT(x,(a+b)*c)MOV(Arr[1,2],y);").unwrap();
        assert_eq!(
            shape(&r),
            "XIC@0(a) [@6 XIO@7(b) , XIC@15(c) [@21  , XIO@23(d)]] CPT@31(x|(a+b)*c) MOV@45(Arr[1,2]|y)"
        );
        assert_eq!(shape(&parse("NOP();").unwrap()), "NOP@0()");
        assert_eq!(shape(&parse("TON(T1,?,?) ;  ").unwrap()), "TON@0(T1|?|?)");
        assert!(parse(";").unwrap().is_empty());
    }

    #[test]
    fn malformed_text_is_located() {
        let err = |t: &str| parse(t).unwrap_err();
        assert_eq!(err("XIC(a"), (0, "'XIC(' is never closed with ')'".into()));
        assert_eq!(
            err("XIC(a)[XIO(b);"),
            (6, "branch '[' is never closed with ']'".into())
        );
        assert_eq!(
            err("XIC(a)]OTE(b);"),
            (6, "']' outside any branch '['".into())
        );
        assert_eq!(
            err("XIC(a)OTE(b)"),
            (12, "the rung text does not end with ';'".into())
        );
        assert_eq!(
            err("XIC(a)OTE b;"),
            (
                6,
                "instruction 'OTE' without its operands in parentheses".into()
            )
        );
        assert_eq!(err("XIC(a])"), (5, "unbalanced ']' in 'XIC(...)'".into()));
        assert_eq!(
            err("XIC(a);x"),
            (7, "'x' after the rung's closing ';'".into())
        );
        assert_eq!(err("XIC(a)?;"), (6, "unexpected '?'".into()));
        let deep = "[".repeat(100) + "XIC(a)" + &"]".repeat(100) + ";";
        assert_eq!(err(&deep), (64, "branches nested deeper than 64".into()));
    }
}
