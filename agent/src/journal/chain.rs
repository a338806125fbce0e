//! The command rows' hash chain: each row of `commands` carries its
//! position in the chain (`chain_index`), the hash of the command row
//! before it (`prev_hash`) and its own (`hash`), a SHA-256 over
//! [`encode`]: every field of the row and those two, length-prefixed.
//! Editing a row breaks its hash; deleting one leaves a gap in the
//! positions; inserting one repeats a position or carries no hash.
//! [`verify`] walks the rows in journal order and names the first that
//! does not hold (`cellwatch audit verify`).
//!
//! Rows written before the chain existed (a journal of an older agent)
//! have no hash and come first: they are counted as "before the chain".
//! Rows purged by the retention leave the chain starting at a later
//! position; it is checked from the oldest row kept. The chain is
//! tamper-evident, not tamper-proof: whoever can write the file can
//! rewrite every hash after an edit, or cut the end, unless the last hash
//! is kept elsewhere too: the writer says the end as committed
//! ([`Link`]), the agent signs it on the bus (its state and snapshot), and
//! [`against`] compares a file with the end so announced.
//!
//! Owns the encoding, the insert of a command row ([`insert`], in the
//! writer's transaction) and the check.

use rusqlite::Connection;
use sha2::{Digest, Sha256};

/// The first field of every encoded row.
pub(crate) const CHAIN_VERSION: &str = "cellwatch-journal-command-v1";

/// What the first row of the chain follows: 64 zeros.
pub(crate) const GENESIS: &str = "0000000000000000000000000000000000000000000000000000000000000000";

/// A command row's fields, as chained.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChainedRow<'a> {
    /// Row number in the journal.
    pub seq: i64,
    /// When, ms since the epoch.
    pub at_ms: i64,
    /// Who.
    pub operator: &'a str,
    /// What.
    pub action: &'a str,
    /// The alarm, tag, transition or chart.
    pub alarm: &'a str,
    /// The command's nonce.
    pub nonce: &'a str,
    /// Carried out.
    pub accepted: bool,
    /// Its signature verified.
    pub verified: bool,
    /// What it did, or why not.
    pub detail: &'a str,
    /// Which row of its command.
    pub stage: &'a str,
    /// Where it came from (refused rows).
    pub source: &'a str,
    /// How many refusals it stands for.
    pub count: i64,
}

/// The bytes hashed for `row` at chain position `index` after `prev`: the
/// version, then every field as `<byte length>:<bytes>\n`.
pub(crate) fn encode(row: &ChainedRow<'_>, index: i64, prev: &str) -> Vec<u8> {
    let mut out = Vec::with_capacity(256 + row.detail.len());
    let fields: [&str; 15] = [
        CHAIN_VERSION,
        &index.to_string(),
        prev,
        &row.seq.to_string(),
        &row.at_ms.to_string(),
        row.operator,
        row.action,
        row.alarm,
        row.nonce,
        if row.accepted { "1" } else { "0" },
        if row.verified { "1" } else { "0" },
        row.detail,
        row.stage,
        row.source,
        &row.count.to_string(),
    ];
    for f in fields {
        out.extend_from_slice(format!("{}:", f.len()).as_bytes());
        out.extend_from_slice(f.as_bytes());
        out.push(b'\n');
    }
    out
}

/// The hex SHA-256 of [`encode`].
pub(crate) fn hash(row: &ChainedRow<'_>, index: i64, prev: &str) -> String {
    hex::encode(Sha256::digest(encode(row, index, prev)))
}

/// The end of the chain: the last chained row's position, sequence number
/// and hash (what the agent's signed state carries on the bus, so that
/// rows cut off the end are found: [`against`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Link {
    /// Its position (0: no row yet).
    pub index: i64,
    /// Its sequence number in the journal (0: no row yet).
    pub seq: i64,
    /// Its hash ([`GENESIS`] before the first row).
    pub hash: String,
}

impl Default for Link {
    fn default() -> Link {
        Link {
            index: 0,
            seq: 0,
            hash: GENESIS.into(),
        }
    }
}

impl Link {
    /// As the agent's signed state and snapshot carry it.
    pub fn announced(&self) -> crate::payload::CommandChain {
        crate::payload::CommandChain {
            position: self.index,
            seq: self.seq,
            hash: self.hash.clone(),
        }
    }

    /// The head carried on the bus.
    pub fn from_announced(head: &crate::payload::CommandChain) -> Link {
        Link {
            index: head.position,
            seq: head.seq,
            hash: head.hash.clone(),
        }
    }

    /// The link of `row`, chained after this one.
    pub fn next(&self, row: &ChainedRow<'_>) -> Link {
        Link {
            index: self.index + 1,
            seq: row.seq,
            hash: hash(row, self.index + 1, &self.hash),
        }
    }

    /// The end of the chain in `conn`'s journal.
    ///
    /// # Errors
    /// SQLite failing.
    pub fn last(conn: &Connection) -> rusqlite::Result<Link> {
        let last = conn.query_row(
            "SELECT chain_index, seq, hash FROM commands WHERE hash IS NOT NULL ORDER BY seq DESC LIMIT 1",
            [],
            |r| {
                Ok(Link {
                    index: r.get(0)?,
                    seq: r.get(1)?,
                    hash: r.get(2)?,
                })
            },
        );
        match last {
            Ok(link) => Ok(link),
            Err(rusqlite::Error::QueryReturnedNoRows) => Ok(Link::default()),
            Err(e) => Err(e),
        }
    }
}

/// Inserts `row` into `commands`, chained after `prev`, with its
/// command's digest beside the chain (not hashed: a lookup for replays,
/// absent from rows written before it); returns its link.
///
/// # Errors
/// SQLite failing.
pub(crate) fn insert(
    tx: &Connection,
    row: &ChainedRow<'_>,
    digest: Option<&str>,
    prev: &Link,
) -> rusqlite::Result<Link> {
    let link = prev.next(row);
    tx.prepare_cached(
        "INSERT INTO commands (seq, at_ms, operator, action, alarm, nonce, accepted, verified, \
         detail, stage, source, count, chain_index, prev_hash, hash, digest) \
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16)",
    )?
    .execute(rusqlite::params![
        row.seq,
        row.at_ms,
        row.operator,
        row.action,
        row.alarm,
        row.nonce,
        i64::from(row.accepted),
        i64::from(row.verified),
        row.detail,
        row.stage,
        row.source,
        row.count,
        link.index,
        prev.hash,
        link.hash,
        digest
    ])?;
    Ok(link)
}

/// What [`verify`] found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Verdict {
    /// Every chained row holds.
    Intact {
        /// Chained rows checked.
        rows: u64,
        /// Rows before the chain began (no hash).
        before: u64,
        /// The position of the oldest chained row kept (1 unless the
        /// retention purged older ones).
        from: i64,
    },
    /// The first row that does not hold.
    Broken {
        /// Its sequence number.
        seq: i64,
        /// What is wrong.
        what: String,
        /// Chained rows that held before it.
        intact: u64,
    },
}

/// Walks the command rows in journal order and checks the chain.
///
/// # Errors
/// SQLite failing (not a journal, or one without the chain's columns).
pub(crate) fn verify(conn: &Connection) -> rusqlite::Result<Verdict> {
    let mut stmt = conn.prepare(
        "SELECT seq, at_ms, operator, action, alarm, nonce, accepted, verified, detail, stage, \
         source, count, chain_index, prev_hash, hash FROM commands ORDER BY seq",
    )?;
    let mut rows = stmt.query([])?;
    let mut before = 0;
    let mut intact = 0;
    let mut from = 0;
    // The last chained row: its sequence number and link.
    let mut last: Option<(i64, Link)> = None;
    while let Some(r) = rows.next()? {
        use rusqlite::types::Value;
        let seq: i64 = r.get(0)?;
        let broken = |what: String| Verdict::Broken { seq, what, intact };
        // A value of another type than the writer wrote is an edit too.
        let mut wrong_type = false;
        let mut text = |i: usize| -> rusqlite::Result<Option<String>> {
            Ok(match r.get::<_, Value>(i)? {
                Value::Text(t) => Some(t),
                Value::Null => None,
                _ => {
                    wrong_type = true;
                    None
                }
            })
        };
        let fields = [2, 3, 4, 5, 8, 9, 10, 13, 14].map(&mut text);
        let mut int = |i: usize| -> rusqlite::Result<Option<i64>> {
            Ok(match r.get::<_, Value>(i)? {
                Value::Integer(n) => Some(n),
                Value::Null => None,
                _ => {
                    wrong_type = true;
                    None
                }
            })
        };
        let numbers = [1, 6, 7, 11, 12].map(&mut int);
        let [operator, action, alarm, nonce, detail, stage, source, prev, stored] = fields;
        let [at_ms, accepted, verified, count, index] = numbers;
        let text = |t: &Option<String>| t.clone().unwrap_or_default();
        let (operator, action, alarm, nonce) = (
            text(&operator?),
            text(&action?),
            text(&alarm?),
            text(&nonce?),
        );
        let (detail, stage, source) = (text(&detail?), text(&stage?), text(&source?));
        let (prev, stored) = (prev?, stored?);
        let row = ChainedRow {
            seq,
            at_ms: at_ms?.unwrap_or_default(),
            operator: &operator,
            action: &action,
            alarm: &alarm,
            nonce: &nonce,
            accepted: accepted?.unwrap_or_default() != 0,
            verified: verified?.unwrap_or_default() != 0,
            detail: &detail,
            stage: &stage,
            source: &source,
            count: count?.unwrap_or_default(),
        };
        let index = index?;
        if wrong_type && last.is_some() {
            return Ok(broken(
                "edited: a field holds a value of another type than the one written".into(),
            ));
        }
        let (Some(index), Some(prev), Some(stored)) = (index, prev, stored) else {
            if last.is_none() {
                before += 1;
                continue;
            }
            return Ok(broken(
                "not in the chain: no hash after the chain began (a row inserted, or its hash removed)"
                    .into(),
            ));
        };
        if let Some((last_seq, link)) = &last {
            if index > link.index + 1 {
                let n = index - link.index - 1;
                return Ok(broken(format!(
                    "{n} command row{} deleted before it (chain position {index} follows {} at seq {last_seq})",
                    if n == 1 { "" } else { "s" },
                    link.index
                )));
            }
            if index <= link.index {
                return Ok(broken(format!(
                    "inserted: chain position {index} comes again after position {} at seq {last_seq}",
                    link.index
                )));
            }
            if prev != link.hash {
                return Ok(broken(format!(
                    "does not follow seq {last_seq}: that row was edited and hashed again, or replaced"
                )));
            }
        } else {
            from = index;
        }
        if hash(&row, index, &prev) != stored {
            return Ok(broken("edited: its fields do not match its hash".into()));
        }
        intact += 1;
        last = Some((
            seq,
            Link {
                index,
                seq,
                hash: stored,
            },
        ));
    }
    Ok(Verdict::Intact {
        rows: intact,
        before,
        from,
    })
}

/// How a journal's chain stands against the head the agent announced
/// (its signed state or snapshot on the bus).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Against {
    /// The announced head is in the journal, with its hash; `after` rows
    /// were chained since it was announced.
    Holds {
        /// Chained rows after it.
        after: i64,
    },
    /// Rows announced are missing from the end: the journal's chain ends
    /// at `ends` (position, seq), before the announced head.
    CutOff {
        /// How many chained rows are missing.
        missing: i64,
        /// The journal's last chained row.
        ends: Link,
    },
    /// The row at the announced position is another than the one
    /// announced (the chain rewritten from there, or forked after a cut).
    Rewritten {
        /// The journal's row at that position.
        seq: i64,
    },
    /// The announced position is older than the oldest row kept (purged
    /// by the retention): nothing to compare.
    Purged,
}

/// Compares the chain in `conn` with the head `announced` by the agent.
///
/// # Errors
/// SQLite failing.
pub(crate) fn against(conn: &Connection, announced: &Link) -> rusqlite::Result<Against> {
    let ends = Link::last(conn)?;
    if announced.index > ends.index {
        return Ok(Against::CutOff {
            missing: announced.index - ends.index,
            ends,
        });
    }
    if announced.index == 0 {
        return Ok(Against::Holds { after: ends.index });
    }
    let at = conn.query_row(
        "SELECT seq, hash FROM commands WHERE chain_index = ?1 AND hash IS NOT NULL ORDER BY seq LIMIT 1",
        [announced.index],
        |r| Ok((r.get::<_, i64>(0)?, r.get::<_, String>(1)?)),
    );
    match at {
        Ok((seq, hash)) if seq == announced.seq && hash == announced.hash => Ok(Against::Holds {
            after: ends.index - announced.index,
        }),
        Ok((seq, _)) => Ok(Against::Rewritten { seq }),
        Err(rusqlite::Error::QueryReturnedNoRows) => Ok(Against::Purged),
        Err(e) => Err(e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(detail: &str) -> ChainedRow<'_> {
        ChainedRow {
            seq: 7,
            at_ms: 1,
            operator: "kim",
            action: "ack",
            alarm: "ese",
            nonce: "00112233445566778899aabbccddeeff",
            accepted: true,
            verified: true,
            detail,
            stage: "command",
            source: "",
            count: 1,
        }
    }

    #[test]
    fn the_encoding_is_length_prefixed() {
        let text = String::from_utf8(encode(&row("ack ese by kim"), 1, GENESIS)).unwrap();
        assert!(
            text.starts_with("28:cellwatch-journal-command-v1\n1:1\n64:000"),
            "{text}"
        );
        assert!(
            text.ends_with("\n14:ack ese by kim\n7:command\n0:\n1:1\n"),
            "{text}"
        );
        // A field's end moved into the next is another text.
        let a = ChainedRow {
            operator: "ki",
            action: "mack",
            ..row("")
        };
        assert_ne!(hash(&a, 1, GENESIS), hash(&row(""), 1, GENESIS));
    }
}
