//! The console's users file: names, roles and argon2id password hashes with their own salts.
//!
//! ```xml
//! <users>
//!   <user name="ana" roles="pilot designer" password="$argon2id$v=19$m=19456,t=2,p=1$…"/>
//! </users>
//! ```
//!
//! [`Users::verify`] spends the same work on an unknown name as on a wrong password, so the answer
//! time does not tell which names exist. [`add_user`] writes a user (`seabus user add`).

use argon2::Argon2;
use argon2::password_hash::{PasswordHash, PasswordHasher, PasswordVerifier, SaltString};
use seabus_medium::xml::{self, FileError};
use std::path::Path;

/// A user who may log in.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct User {
    /// The log-in name.
    pub name: String,
    /// The roles, in the file's order.
    pub roles: Vec<String>,
    /// The argon2id hash (PHC string).
    hash: String,
}

impl User {
    /// Whether the user has `role`.
    pub fn has(&self, role: &str) -> bool {
        self.roles.iter().any(|r| r == role)
    }
}

/// Every user of a console.
#[derive(Debug, Clone, Default)]
pub struct Users {
    users: Vec<User>,
}

/// A hash to verify against when the name is unknown (the same work as a real one).
fn decoy() -> &'static str {
    static DECOY: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    DECOY.get_or_init(|| hash_password("a password no one has").unwrap_or_default())
}

/// The argon2id hash of `password` with a fresh random salt, as a PHC string.
pub fn hash_password(password: &str) -> Result<String, String> {
    let mut salt = [0u8; 16];
    getrandom::fill(&mut salt).map_err(|e| format!("no random salt: {e}"))?;
    let salt = SaltString::encode_b64(&salt).map_err(|e| e.to_string())?;
    Argon2::default()
        .hash_password(password.as_bytes(), &salt)
        .map(|h| h.to_string())
        .map_err(|e| e.to_string())
}

/// A fresh random password of 16 letters and digits (the demo's users get these).
pub fn random_password() -> Result<String, String> {
    const CHARS: &[u8] = b"abcdefghijkmnpqrstuvwxyzABCDEFGHJKLMNPQRSTUVWXYZ23456789";
    let mut out = String::new();
    // bytes past the last whole multiple of the alphabet are skipped: every character as likely
    let limit = 256 - 256 % CHARS.len();
    for _ in 0..64 {
        let mut bytes = [0u8; 32];
        getrandom::fill(&mut bytes).map_err(|e| format!("no randomness: {e}"))?;
        for b in bytes.iter().map(|b| usize::from(*b)).filter(|b| *b < limit) {
            out.push(CHARS[b % CHARS.len()] as char);
            if out.len() == 16 {
                return Ok(out);
            }
        }
    }
    Err("no randomness".into())
}

/// Whether a name or role is acceptable: letters, digits, `_`, `-`, `.`, `@`; at most 64.
pub fn is_name(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 64
        && s.chars()
            .all(|c| c.is_alphanumeric() || matches!(c, '_' | '-' | '.' | '@'))
}

impl Users {
    /// Reads a users file.
    pub fn load(path: &Path) -> Result<Users, FileError> {
        let root = xml::parse_file(path)?;
        Users::from_element(&root)
    }

    /// Reads users file text (`file` names it in errors).
    pub fn parse(file: &str, text: &str) -> Result<Users, FileError> {
        Users::from_element(&xml::parse(file, text)?)
    }

    fn from_element(root: &xml::Element) -> Result<Users, FileError> {
        if root.name != "users" {
            return Err(root.error(format!(
                "the root element is <{}>; a users file holds <users>",
                root.name
            )));
        }
        root.only_attrs(&[])?;
        root.only_children(&["user"])?;
        let mut users: Vec<User> = Vec::new();
        for u in &root.children {
            u.only_attrs(&["name", "roles", "password"])?;
            let name = u.required("name")?;
            if !is_name(&name.value) {
                return Err(name.error(format!(
                    "`{}` is not a user name (letters, digits, _ - . @)",
                    name.value
                )));
            }
            if users.iter().any(|o| o.name == name.value) {
                return Err(name.error(format!("user `{}` twice", name.value)));
            }
            let roles: Vec<String> = u
                .get("roles")
                .unwrap_or("")
                .split_whitespace()
                .map(str::to_string)
                .collect();
            if let Some(bad) = roles.iter().find(|r| !is_name(r)) {
                let attr = u.required("roles")?;
                return Err(attr.error(format!("`{bad}` is not a role name")));
            }
            let password = u.required("password")?;
            match PasswordHash::new(&password.value) {
                Ok(h) if h.algorithm.as_str().starts_with("argon2") => {}
                Ok(h) => {
                    return Err(password.error(format!(
                        "a {} hash; passwords are argon2id hashes (seabus user add writes them)",
                        h.algorithm
                    )));
                }
                Err(e) => {
                    return Err(password.error(format!(
                        "not a password hash ({e}); passwords are argon2id hashes, never plain \
                         text (seabus user add writes them)"
                    )));
                }
            }
            users.push(User {
                name: name.value.clone(),
                roles,
                hash: password.value.clone(),
            });
        }
        Ok(Users { users })
    }

    /// Users with these passwords (hashed here), for a console built in code such as the demo's.
    pub fn with_passwords(list: &[(&str, &[&str], &str)]) -> Result<Users, String> {
        let mut users = Vec::new();
        for (name, roles, password) in list {
            users.push(User {
                name: name.to_string(),
                roles: roles.iter().map(|r| r.to_string()).collect(),
                hash: hash_password(password)?,
            });
        }
        Ok(Users { users })
    }

    /// The user called `name`.
    pub fn get(&self, name: &str) -> Option<&User> {
        self.users.iter().find(|u| u.name == name)
    }

    /// Every user.
    pub fn iter(&self) -> impl Iterator<Item = &User> {
        self.users.iter()
    }

    /// The user when `password` is theirs.
    pub fn verify(&self, name: &str, password: &str) -> Option<&User> {
        let user = self.get(name);
        let hash = user.map_or(decoy(), |u| u.hash.as_str());
        let ok = PasswordHash::new(hash).is_ok_and(|h| {
            Argon2::default()
                .verify_password(password.as_bytes(), &h)
                .is_ok()
        });
        user.filter(|_| ok)
    }

    /// The file's text.
    pub fn to_xml(&self) -> String {
        let mut out = String::from("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<users>\n");
        for u in &self.users {
            out += &format!(
                "  <user name=\"{}\" roles=\"{}\" password=\"{}\"/>\n",
                u.name,
                u.roles.join(" "),
                u.hash
            );
        }
        out + "</users>\n"
    }
}

/// Adds user `name` with `roles` and `password` to the users file at `path` (created when missing),
/// replacing a user of that name. The file is replaced atomically.
pub fn add_user(path: &Path, name: &str, roles: &[String], password: &str) -> Result<(), String> {
    if !is_name(name) {
        return Err(format!(
            "`{name}` is not a user name (letters, digits, _ - . @)"
        ));
    }
    if let Some(bad) = roles.iter().find(|r| !is_name(r)) {
        return Err(format!("`{bad}` is not a role name"));
    }
    if password.chars().count() < 8 {
        return Err("a password has at least 8 characters".into());
    }
    let mut users = if path.exists() {
        Users::load(path).map_err(|e| e.to_string())?
    } else {
        Users::default()
    };
    let user = User {
        name: name.to_string(),
        roles: roles.to_vec(),
        hash: hash_password(password)?,
    };
    match users.users.iter_mut().find(|u| u.name == name) {
        Some(u) => *u = user,
        None => users.users.push(user),
    }
    seabus_medium::fs::atomic_write_private(path, users.to_xml().as_bytes())
        .map_err(|e| format!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passwords_verify_and_files_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("users.xml");
        add_user(
            &path,
            "ana",
            &["pilot".into(), "designer".into()],
            "sea-trial-7",
        )
        .unwrap();
        add_user(&path, "ivo", &["scientist".into()], "plankton-42").unwrap();
        let users = Users::load(&path).unwrap();
        let ana = users.verify("ana", "sea-trial-7").expect("right password");
        assert!(ana.has("pilot") && ana.has("designer") && !ana.has("scientist"));
        assert!(users.verify("ana", "sea-trial-8").is_none());
        assert!(users.verify("nobody", "sea-trial-7").is_none());
        // salted: the same password hashes differently
        assert_ne!(hash_password("x").unwrap(), hash_password("x").unwrap());
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("$argon2id$") && !text.contains("sea-trial-7"));
        // replacing a user keeps one entry
        add_user(&path, "ana", &["observer".into()], "new-password").unwrap();
        let users = Users::load(&path).unwrap();
        assert_eq!(users.iter().count(), 2);
        assert!(users.verify("ana", "new-password").unwrap().has("observer"));
        assert!(add_user(&path, "x", &[], "short").is_err());
    }

    #[test]
    fn plain_passwords_and_bad_files_are_refused_with_their_place() {
        let e = Users::parse(
            "u.xml",
            "<users>\n  <user name=\"ana\" roles=\"pilot\" password=\"hunter2\"/>\n</users>",
        )
        .unwrap_err();
        assert!(
            e.to_string().starts_with("u.xml:2:") && e.to_string().contains("never plain text"),
            "{e}"
        );
        let e = Users::parse("u.xml", "<users><person/></users>").unwrap_err();
        assert!(e.to_string().contains("person"), "{e}");
        let e = Users::parse(
            "u.xml",
            "<users><user name=\"a b\" password=\"x\"/></users>",
        )
        .unwrap_err();
        assert!(e.to_string().contains("not a user name"), "{e}");
    }
}
