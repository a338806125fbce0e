//! The alarm server's users (`alarm_server.users_file`): who may open a
//! session with a user name, and the operator each acts as. Passwords are
//! kept as Argon2 PHC strings, never in clear; a user without an operator
//! may browse and subscribe but not acknowledge. An unknown user name
//! costs the same Argon2 verification as a known one, so that how long a
//! refusal takes does not tell which names exist.

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, RwLock};

use argon2::password_hash::{PasswordHash, PasswordHasher, PasswordVerifier, SaltString};
use argon2::{Algorithm, Argon2, Params, Version};
use async_trait::async_trait;
use opcua::server::authenticator::{
    user_pass_security_policy_id, user_pass_security_policy_uri, AuthManager, Password, UserToken,
};
use opcua::server::ServerEndpoint;
use opcua::types::{Error, StatusCode, UAString, UserTokenPolicy, UserTokenType};
use serde::Deserialize;

/// Why the users file cannot be taken.
#[derive(Debug, thiserror::Error)]
pub enum UsersError {
    /// The file cannot be read.
    #[error("{path}: cannot read the alarm server's users: {source}")]
    Read {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// Not TOML of the expected shape.
    #[error("{origin}: {message}")]
    Syntax {
        /// The file.
        origin: String,
        /// What is wrong, as the TOML reader says.
        message: String,
    },
    /// One user's entry is wrong.
    #[error("{origin}: users.{user}: {message}")]
    Entry {
        /// The file.
        origin: String,
        /// The user.
        user: String,
        /// What is wrong.
        message: String,
    },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct UsersFile {
    users: HashMap<String, UserEntry>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct UserEntry {
    operator: Option<String>,
    password_hash: String,
}

/// One user: the operator they act as, and their password's hash.
#[derive(Debug, Clone)]
struct User {
    operator: Option<String>,
    hash: String,
}

/// The users of one reading of the file.
#[derive(Debug, Default)]
struct Table {
    by_name: HashMap<String, User>,
    /// The hash of no one's password, with the parameters of the first
    /// user's (by name; Argon2's defaults, `cellwatch hash-password`'s,
    /// without users): what a password given for an unknown user is
    /// verified against.
    nobody: String,
}

/// The users of the alarm server: clones share them, and a reload
/// replaces them for all ([`Users::replace_with`]).
#[derive(Debug, Clone, Default)]
pub struct Users {
    users: Arc<RwLock<Arc<Table>>>,
}

impl Users {
    /// Parses a users file's text, named `origin`.
    ///
    /// # Errors
    /// Malformed TOML, an unknown key, a user name or operator that is not
    /// letters, digits, `-` or `_`, or a hash that is not a PHC string.
    pub fn parse(origin: &str, text: &str) -> Result<Users, UsersError> {
        let file: UsersFile = toml::from_str(text).map_err(|e| UsersError::Syntax {
            origin: match e.span() {
                Some(span) => {
                    let (line, col) = crate::table::line_col(text, span.start);
                    format!("{origin}:{line}:{col}")
                }
                None => origin.into(),
            },
            message: e.message().into(),
        })?;
        let entry = |user: &str, message: String| UsersError::Entry {
            origin: origin.into(),
            user: user.into(),
            message,
        };
        let mut users = HashMap::new();
        for (name, e) in file.users {
            if !crate::operator::valid_operator_name(&name) {
                return Err(entry(
                    &format!("{name:?}"),
                    "a user name is letters, digits, '-' or '_'".into(),
                ));
            }
            if let Some(op) = &e.operator {
                if !crate::operator::valid_operator_name(op) {
                    return Err(entry(
                        &name,
                        format!("operator: {op:?} is not an operator's name"),
                    ));
                }
            }
            if let Err(why) = PasswordHash::new(&e.password_hash) {
                return Err(entry(
                    &name,
                    format!("password_hash: not an Argon2 PHC string ({why}): make one with `cellwatch hash-password`"),
                ));
            }
            users.insert(
                name,
                User {
                    operator: e.operator,
                    hash: e.password_hash,
                },
            );
        }
        let nobody = nobodys_hash(
            users
                .iter()
                .min_by(|a, b| a.0.cmp(b.0))
                .map(|(_, u)| u.hash.as_str()),
        );
        Ok(Users {
            users: Arc::new(RwLock::new(Arc::new(Table {
                by_name: users,
                nobody,
            }))),
        })
    }

    /// Loads the users file.
    ///
    /// # Errors
    /// The file cannot be read or parsed.
    pub fn load(path: &Path) -> Result<Users, UsersError> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| UsersError::Read {
            path: name.clone(),
            source,
        })?;
        Users::parse(&name, &text)
    }

    /// The users now (a reload may replace them meanwhile).
    fn now(&self) -> Arc<Table> {
        self.users
            .read()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
    }

    /// From now on, `other`'s users (a reload): sessions open stay open,
    /// each acknowledgement and new session is judged by these.
    pub fn replace_with(&self, other: Users) {
        let new = other.now();
        *self
            .users
            .write()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = new;
    }

    /// The operator `user` acts as, if any.
    pub fn operator(&self, user: &str) -> Option<String> {
        self.now().by_name.get(user)?.operator.clone()
    }

    /// What stands between each user acting as an operator and an
    /// acknowledgement, as `gate` (the cell's operators) would say it:
    /// `users.NAME acts as 'OPERATOR': WHY`, sorted by user. A user acting
    /// as nobody is meant to watch, and not named.
    pub fn cannot_acknowledge(&self, gate: &crate::operator::Gate) -> Vec<String> {
        let mut out: Vec<String> = self
            .now()
            .by_name
            .iter()
            .filter_map(|(name, u)| {
                let operator = u.operator.as_deref()?;
                let why = gate.permits(operator, crate::operator::Action::Ack).err()?;
                Some(format!(
                    "users.{}: acts as '{}': {why}",
                    crate::operator::escaped(name),
                    crate::operator::escaped(operator)
                ))
            })
            .collect();
        out.sort();
        out
    }

    /// Whether `password` is `user`'s (Argon2, so slow on purpose: run it
    /// off the server's tasks). An unknown user's password is verified all
    /// the same, against no one's hash, and refused.
    pub(crate) fn verify(&self, user: &str, password: &str) -> bool {
        let users = self.now();
        match users.by_name.get(user) {
            Some(u) => argon2_verify(&u.hash, password),
            None => {
                let _same_cost = argon2_verify(&users.nobody, password);
                false
            }
        }
    }
}

/// Whether `password` matches the PHC string `hash` (with the algorithm
/// and parameters it names).
fn argon2_verify(hash: &str, password: &str) -> bool {
    #[cfg(test)]
    tests::VERIFICATIONS.with(|n| n.set(n.get() + 1));
    PasswordHash::new(hash).is_ok_and(|h| {
        Argon2::default()
            .verify_password(password.as_bytes(), &h)
            .is_ok()
    })
}

/// A hash of no one's password (random, thrown away) with the algorithm,
/// version and parameters of `like` when it reads, else Argon2's defaults.
fn nobodys_hash(like: Option<&str>) -> String {
    let argon2 = like
        .and_then(|h| PasswordHash::new(h).ok())
        .and_then(|h| {
            Some(Argon2::new(
                Algorithm::try_from(h.algorithm).ok()?,
                Version::try_from(h.version?).ok()?,
                Params::try_from(&h).ok()?,
            ))
        })
        .unwrap_or_default();
    let salt = SaltString::generate(&mut argon2::password_hash::rand_core::OsRng);
    let password = SaltString::generate(&mut argon2::password_hash::rand_core::OsRng);
    argon2
        .hash_password(password.as_str().as_bytes(), &salt)
        .map(|h| h.to_string())
        .unwrap_or_else(|_| hash_password(password.as_str()))
}

/// `password`'s Argon2id hash as a PHC string, with a fresh salt.
///
/// # Panics
/// Never for a password: Argon2's defaults take any length used here.
pub fn hash_password(password: &str) -> String {
    let salt = SaltString::generate(&mut argon2::password_hash::rand_core::OsRng);
    Argon2::default()
        .hash_password(password.as_bytes(), &salt)
        .expect("Argon2 with its default parameters hashes any password")
        .to_string()
}

#[async_trait]
impl AuthManager for Users {
    /// Anyone may browse and subscribe; acknowledging asks for a user.
    async fn authenticate_anonymous_token(&self, _endpoint: &ServerEndpoint) -> Result<(), Error> {
        Ok(())
    }

    async fn authenticate_username_identity_token(
        &self,
        _endpoint: &ServerEndpoint,
        username: &str,
        password: &Password,
    ) -> Result<UserToken, Error> {
        let users = self.clone();
        let (name, pass) = (username.to_string(), password.get().to_string());
        let ok = tokio::task::spawn_blocking(move || users.verify(&name, &pass))
            .await
            .unwrap_or(false);
        if ok {
            Ok(UserToken(username.to_string()))
        } else {
            tracing::warn!(user = %crate::operator::escaped(username), "alarm server: a session refused: unknown user or wrong password");
            Err(Error::new(
                StatusCode::BadIdentityTokenRejected,
                "unknown user or wrong password",
            ))
        }
    }

    fn user_token_policies(&self, endpoint: &ServerEndpoint) -> Vec<UserTokenPolicy> {
        let mut policies = vec![UserTokenPolicy {
            policy_id: user_pass_security_policy_id(endpoint),
            token_type: UserTokenType::UserName,
            issued_token_type: UAString::null(),
            issuer_endpoint_url: UAString::null(),
            security_policy_uri: user_pass_security_policy_uri(endpoint),
        }];
        policies.push(UserTokenPolicy {
            // The library's own id for the anonymous policy.
            policy_id: "anonymous".into(),
            token_type: UserTokenType::Anonymous,
            issued_token_type: UAString::null(),
            issuer_endpoint_url: UAString::null(),
            security_policy_uri: UAString::null(),
        });
        policies
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    thread_local! {
        /// Argon2 verifications run on this thread.
        pub(super) static VERIFICATIONS: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
    }

    /// How many Argon2 verifications `f` ran.
    fn verifications(f: impl FnOnce() -> bool) -> (bool, u64) {
        let before = VERIFICATIONS.with(std::cell::Cell::get);
        let ok = f();
        (ok, VERIFICATIONS.with(std::cell::Cell::get) - before)
    }

    #[test]
    fn an_unknown_user_costs_the_verification_a_known_one_does() {
        let hash = hash_password("s3cret");
        let text = format!("[users.scada-kim]\noperator = \"kim\"\npassword_hash = \"{hash}\"\n");
        let users = Users::parse("users.toml", &text).unwrap();
        assert_eq!(
            verifications(|| users.verify("scada-kim", "s3cret")),
            (true, 1)
        );
        assert_eq!(
            verifications(|| users.verify("scada-kim", "wrong")),
            (false, 1)
        );
        assert_eq!(
            verifications(|| users.verify("scada-kym", "s3cret")),
            (false, 1)
        );
        // No one's hash has the users' parameters, and takes no password.
        let table = users.now();
        let (ours, nobodys) = (
            PasswordHash::new(&table.by_name["scada-kim"].hash).unwrap(),
            PasswordHash::new(&table.nobody).unwrap(),
        );
        assert_eq!(
            (
                nobodys.algorithm,
                nobodys.version,
                nobodys.params.to_string()
            ),
            (ours.algorithm, ours.version, ours.params.to_string())
        );
        assert!(!argon2_verify(&table.nobody, ""));
        // Other parameters are followed; no users, Argon2's defaults.
        let light = Argon2::new(
            Algorithm::Argon2id,
            Version::V0x13,
            Params::new(8192, 1, 1, None).unwrap(),
        )
        .hash_password(
            b"s3cret",
            &SaltString::generate(&mut argon2::password_hash::rand_core::OsRng),
        )
        .unwrap()
        .to_string();
        let nobody = nobodys_hash(Some(&light));
        assert!(nobody.contains("$m=8192,t=1,p=1$"), "{nobody}");
        let empty = Users::parse("users.toml", "[users]\n").unwrap();
        assert_eq!(verifications(|| empty.verify("anyone", "x")), (false, 1));
        assert!(empty.now().nobody.contains("$m=19456,t=2,p=1$"));
    }

    #[test]
    fn a_user_acts_as_an_operator_by_password() {
        let hash = hash_password("s3cret");
        let text = format!(
            "[users.scada-kim]\noperator = \"kim\"\npassword_hash = \"{hash}\"\n[users.viewer]\npassword_hash = \"{hash}\"\n"
        );
        let users = Users::parse("users.toml", &text).unwrap();
        assert_eq!(users.operator("scada-kim").as_deref(), Some("kim"));
        assert_eq!(users.operator("viewer"), None);
        assert!(users.verify("scada-kim", "s3cret"));
        assert!(!users.verify("scada-kim", "secret"));
        assert!(!users.verify("nobody", "s3cret"));
        let bad = "[users.x]\noperator = \"kim\"\npassword_hash = \"s3cret\"\n";
        assert_eq!(
            Users::parse("users.toml", bad).unwrap_err().to_string(),
            "users.toml: users.x: password_hash: not an Argon2 PHC string (password hash string missing field): make one with `cellwatch hash-password`"
        );
    }

    #[test]
    fn a_missing_hash_is_located() {
        let bad = "[users.x]\noperator = \"kim\"\n";
        assert_eq!(
            Users::parse("users.toml", bad).unwrap_err().to_string(),
            "users.toml:1:1: missing field `password_hash`"
        );
    }

    #[test]
    fn who_cannot_acknowledge_is_named() {
        use crate::operator::{Action, Gate, OperatorKey, OperatorKeys};
        let hash = hash_password("s3cret");
        let text = format!(
            "[users.scada-kim]\noperator = \"kim\"\npassword_hash = \"{hash}\"\n\
             [users.scada-ana]\noperator = \"ana\"\npassword_hash = \"{hash}\"\n\
             [users.scada-lee]\noperator = \"lee\"\npassword_hash = \"{hash}\"\n\
             [users.viewer]\npassword_hash = \"{hash}\"\n"
        );
        let users = Users::parse("users.toml", &text).unwrap();
        let operators = OperatorKey::generate("kim").operators_entry(&[Action::Ack])
            + &OperatorKey::generate("ana").operators_entry(&[Action::Reset]);
        let gate = Gate::new(
            "m01",
            OperatorKeys::parse("operators.toml", &operators).unwrap(),
        );
        assert_eq!(
            users.cannot_acknowledge(&gate),
            [
                "users.scada-ana: acts as 'ana': operator 'ana' may not ack",
                "users.scada-lee: acts as 'lee': unknown operator 'lee'",
            ]
        );
    }
}
