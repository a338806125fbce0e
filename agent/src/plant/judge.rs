//! An agent's signed `about` judged against what the plant deployed to
//! it (pure): the facts and problems `cellwatch plant check` prints and
//! the console's Agents page shows. What was deployed is read from the
//! plant's folder by the check, and from the file `cellwatch plant`
//! writes for the console (`plant-deployed.json`, [`DeployedPlant`]).

use std::collections::BTreeMap;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::payload::AboutPayload;

/// A certificate ending sooner than this is a problem.
pub(crate) const EXPIRY_WARNING: Duration = Duration::from_secs(30 * 86_400);

/// The schema of the file the console reads what was deployed from.
pub(crate) const DEPLOYED_SCHEMA: &str = "cellwatch.plant-deployed.v1";

/// The largest such file the console reads.
pub(crate) const MAX_DEPLOYED_BYTES: u64 = 4 << 20;

/// What the plant deployed, as of the last `cellwatch plant` run.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct DeployedPlant {
    /// [`DEPLOYED_SCHEMA`].
    pub schema: String,
    /// The plant's signed operators list's version, when it has one.
    pub operators_version: Option<u64>,
    /// Each cell's, by id.
    pub cells: BTreeMap<String, DeployedCell>,
}

/// What the plant deployed to one cell's host.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct DeployedCell {
    /// Its configuration file, as the plant's folder names it.
    pub config: String,
    /// SHA-256 (hex) of that file, or why it cannot be read.
    pub config_sha256: Result<String, Unreadable>,
    /// Its bus certificate, as the plant's folder names it.
    pub bus_certificate: String,
    /// SHA-256 (hex) of that certificate's DER bytes, when it reads.
    pub bus_certificate_sha256: Option<String>,
    /// Its signing key file, as the plant's folder names it.
    pub signing_key: String,
    /// The signing keys (hex) it is being rotated from.
    pub rotated_from: Vec<String>,
}

/// Why a file the plant deployed could not be read when the plant was
/// made: the system's words, kept in the deployed file as they were said
/// (a plain string in it).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, thiserror::Error)]
#[serde(transparent)]
#[error("{0}")]
pub(crate) struct Unreadable(pub String);

impl From<std::io::Error> for Unreadable {
    fn from(e: std::io::Error) -> Unreadable {
        Unreadable(e.to_string())
    }
}

/// What an agent's answer says: as it should be, and wrong (each with what
/// to do).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub(crate) struct Judged {
    /// What is as it should be.
    pub facts: Vec<String>,
    /// What is wrong.
    pub problems: Vec<String>,
}

/// What a certificate's end means at `now_ms`.
pub(crate) fn expiry(what: &str, not_after_ms: u64, now_ms: u64, j: &mut Judged) {
    let day = 86_400_000;
    if not_after_ms <= now_ms {
        j.problems.push(format!(
            "{what} ended {}: renew it (cellwatch plant renew)",
            crate::clock::rfc3339(not_after_ms)
        ));
    } else if not_after_ms - now_ms < EXPIRY_WARNING.as_millis() as u64 {
        j.problems.push(format!(
            "{what} ends in {} days ({}): renew it",
            (not_after_ms - now_ms) / day,
            crate::clock::rfc3339(not_after_ms)
        ));
    } else {
        j.facts.push(format!(
            "{what} until {}",
            &crate::clock::rfc3339(not_after_ms)[..10]
        ));
    }
}

/// Cell `id`'s agent's `about`, judged at `now_ms` against this
/// version, what was `deployed` to it (when known) and the plant's
/// operators list's version (when it has one).
pub(crate) fn judge(
    id: &str,
    about: &AboutPayload,
    deployed: Option<&DeployedCell>,
    operators_version: Option<u64>,
    now_ms: u64,
) -> Judged {
    let mut j = Judged::default();
    let ours = env!("CARGO_PKG_VERSION");
    if about.version == ours {
        j.facts.push(format!("cellwatch {ours}"));
    } else {
        j.problems.push(format!(
            "its agent runs cellwatch {}, the plant's is {ours}",
            about.version
        ));
    }
    if let Some(d) = deployed {
        match &d.config_sha256 {
            Ok(sha) if *sha == about.config_sha256 => {
                j.facts.push("runs the configuration deployed".into());
            }
            Ok(_) => j.problems.push(format!(
                "its agent runs another configuration than {} (copy it to the host and reload: systemctl reload cellwatch@{id})",
                d.config
            )),
            Err(e) => j.problems.push(format!("{}: {e}", d.config)),
        }
    }
    match (operators_version, about.operators_version) {
        (Some(ours), Some(v)) if v == ours => j.facts.push(format!("operators list v{v}")),
        (Some(ours), held) => j.problems.push(format!(
            "its agent judges commands by {}, the plant's list is v{ours}: cellwatch plant publish",
            held.map_or_else(
                || "its operators file".to_string(),
                |v| format!("operators list v{v}")
            )
        )),
        (None, _) => {}
    }
    if let Some(d) = deployed {
        if d.rotated_from.contains(&about.signing_key) {
            j.problems.push(format!(
                "its agent still signs with the key it is being rotated from: copy {} to it and restart cellwatch@{id}",
                d.signing_key
            ));
        }
        if let (Some(c), Some(sha)) = (&about.bus_certificate, &d.bus_certificate_sha256) {
            if &c.sha256 != sha {
                j.problems.push(format!(
                    "its agent runs with another bus certificate than {} (renewed: copy it and its key to the host and restart cellwatch@{id})",
                    d.bus_certificate
                ));
            }
        }
    }
    if let Some(c) = &about.bus_certificate {
        let end = crate::clock::parse_time(&c.not_after, now_ms).unwrap_or(0);
        let mut certificate = Judged::default();
        expiry(
            "the certificate it runs with",
            end,
            now_ms,
            &mut certificate,
        );
        j.problems.extend(certificate.problems);
    }
    j
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::CertificateAbout;

    const NOW: u64 = 1_800_000_000_000;

    fn about() -> AboutPayload {
        AboutPayload {
            schema: crate::payload::ABOUT_SCHEMA.into(),
            cell: "m01".into(),
            version: env!("CARGO_PKG_VERSION").into(),
            config_sha256: "aa".into(),
            signing_key: "k2".into(),
            bus_certificate: Some(CertificateAbout {
                name: "agent-m01".into(),
                not_after: crate::clock::rfc3339(NOW + 90 * 86_400_000),
                sha256: "cc".into(),
            }),
            started: crate::clock::rfc3339(NOW),
            operators_version: Some(3),
        }
    }

    fn deployed() -> DeployedCell {
        DeployedCell {
            config: "hosts/h1/etc/cellwatch/m01.toml".into(),
            config_sha256: Ok("aa".into()),
            bus_certificate: "hosts/h1/etc/cellwatch/agent-m01.pem".into(),
            bus_certificate_sha256: Some("cc".into()),
            signing_key: "hosts/h1/var/lib/cellwatch/m01/signing.key".into(),
            rotated_from: vec!["k1".into()],
        }
    }

    #[test]
    fn an_agent_as_deployed_is_all_facts() {
        let j = judge("m01", &about(), Some(&deployed()), Some(3), NOW);
        assert!(j.problems.is_empty(), "{j:?}");
        assert_eq!(
            j.facts,
            [
                format!("cellwatch {}", env!("CARGO_PKG_VERSION")),
                "runs the configuration deployed".into(),
                "operators list v3".into(),
            ]
        );
    }

    #[test]
    fn each_difference_is_a_problem_naming_what_to_do() {
        let mut a = about();
        a.version = "0.0.1".into();
        a.config_sha256 = "other".into();
        a.signing_key = "k1".into();
        a.operators_version = Some(2);
        a.bus_certificate = Some(CertificateAbout {
            name: "agent-m01".into(),
            not_after: crate::clock::rfc3339(NOW + 5 * 86_400_000),
            sha256: "old".into(),
        });
        let j = judge("m01", &a, Some(&deployed()), Some(3), NOW);
        let text = j.problems.join("\n");
        for said in [
            "runs cellwatch 0.0.1",
            "another configuration than hosts/h1/etc/cellwatch/m01.toml",
            "operators list v2, the plant's list is v3",
            "rotated from: copy hosts/h1/var/lib/cellwatch/m01/signing.key",
            "another bus certificate than hosts/h1/etc/cellwatch/agent-m01.pem",
            "ends in 5 days",
        ] {
            assert!(text.contains(said), "{said}: {text}");
        }
    }

    #[test]
    fn without_what_was_deployed_only_the_agent_itself_is_judged() {
        let mut a = about();
        a.config_sha256 = "anything".into();
        let j = judge("m01", &a, None, None, NOW);
        assert!(j.problems.is_empty(), "{j:?}");
        assert_eq!(j.facts.len(), 1, "{j:?}");
    }

    #[test]
    fn the_deployed_file_reads_back() {
        let mut p = DeployedPlant {
            schema: DEPLOYED_SCHEMA.into(),
            operators_version: Some(3),
            cells: BTreeMap::new(),
        };
        let mut broken = deployed();
        broken.config_sha256 = Err(Unreadable("No such file or directory".into()));
        p.cells.insert("m01".into(), deployed());
        p.cells.insert("m02".into(), broken);
        let text = serde_json::to_string(&p).unwrap();
        assert_eq!(serde_json::from_str::<DeployedPlant>(&text).unwrap(), p);
    }
}
