//! Paths and names as they cross the wire and become files.
//!
//! * Paths travel between processes as their raw bytes: a Linux path need not
//!   be valid UTF-8 (a scene in a folder named in Latin-1 is legal), and the
//!   protocol must carry it exactly rather than fail or alter it. Readable
//!   formats (TOML) still read and write them as strings.
//! * Names that come from configuration files (projector ids) and become file
//!   names are checked to be one plain path component, so output never
//!   leaves the folder it is written to.

use serde::de::{self, SeqAccess, Visitor};
use serde::{Deserializer, Serializer};
use std::ffi::OsString;
use std::os::unix::ffi::{OsStrExt, OsStringExt};
use std::path::{Path, PathBuf};

/// `#[serde(with = "paths::bytes")]` for a `PathBuf` field.
pub mod bytes {
    use super::*;

    pub fn serialize<S: Serializer>(p: &Path, s: S) -> Result<S::Ok, S::Error> {
        if s.is_human_readable() {
            match p.to_str() {
                Some(t) => s.serialize_str(t),
                None => Err(serde::ser::Error::custom(format!(
                    "path {} is not valid UTF-8",
                    p.display()
                ))),
            }
        } else {
            s.serialize_bytes(p.as_os_str().as_bytes())
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<PathBuf, D::Error> {
        d.deserialize_byte_buf(PathVisitor)
    }
}

/// `#[serde(with = "paths::opt_bytes")]` for an `Option<PathBuf>` field.
pub mod opt_bytes {
    use super::*;

    pub fn serialize<S: Serializer>(p: &Option<PathBuf>, s: S) -> Result<S::Ok, S::Error> {
        struct Wrap<'a>(&'a Path);
        impl serde::Serialize for Wrap<'_> {
            fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                bytes::serialize(self.0, s)
            }
        }
        match p {
            Some(p) => s.serialize_some(&Wrap(p)),
            None => s.serialize_none(),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<PathBuf>, D::Error> {
        struct OptVisitor;
        impl<'de> Visitor<'de> for OptVisitor {
            type Value = Option<PathBuf>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("an optional path")
            }
            fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
                Ok(None)
            }
            fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
                Ok(None)
            }
            fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
                bytes::deserialize(d).map(Some)
            }
        }
        d.deserialize_option(OptVisitor)
    }
}

/// `#[serde(with = "paths::list_bytes")]` for a `Vec<PathBuf>` field.
pub mod list_bytes {
    use super::*;

    struct Wrap(PathBuf);
    impl serde::Serialize for Wrap {
        fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            bytes::serialize(&self.0, s)
        }
    }
    impl<'de> serde::Deserialize<'de> for Wrap {
        fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
            bytes::deserialize(d).map(Wrap)
        }
    }

    pub fn serialize<S: Serializer>(p: &[PathBuf], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(p.iter().map(|p| Wrap(p.clone())))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<PathBuf>, D::Error> {
        let v: Vec<Wrap> = serde::Deserialize::deserialize(d)?;
        Ok(v.into_iter().map(|w| w.0).collect())
    }
}

struct PathVisitor;

impl<'de> Visitor<'de> for PathVisitor {
    type Value = PathBuf;

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a path")
    }

    fn visit_str<E: de::Error>(self, v: &str) -> Result<PathBuf, E> {
        Ok(PathBuf::from(v))
    }

    fn visit_bytes<E: de::Error>(self, v: &[u8]) -> Result<PathBuf, E> {
        Ok(PathBuf::from(OsString::from_vec(v.to_vec())))
    }

    fn visit_byte_buf<E: de::Error>(self, v: Vec<u8>) -> Result<PathBuf, E> {
        Ok(PathBuf::from(OsString::from_vec(v)))
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<PathBuf, A::Error> {
        let mut v = Vec::with_capacity(seq.size_hint().unwrap_or(0));
        while let Some(b) = seq.next_element::<u8>()? {
            v.push(b);
        }
        Ok(PathBuf::from(OsString::from_vec(v)))
    }
}

/// Checks that `name` can stand as one file name inside an output folder: not
/// empty, no separator, not `.` or `..`, no NUL, no control characters, at
/// most 200 bytes. `what` names the file and field in the error.
pub fn check_file_component(name: &str, what: &str) -> anyhow::Result<()> {
    let bad = if name.is_empty() {
        Some("is empty")
    } else if name == "." || name == ".." {
        Some("is '.' or '..'")
    } else if name.contains('/') || name.contains('\\') {
        Some("contains a path separator")
    } else if name.chars().any(|c| c.is_control()) {
        Some("contains a control character")
    } else if name.len() > 200 {
        Some("is longer than 200 bytes")
    } else {
        None
    };
    match bad {
        Some(why) => anyhow::bail!(
            "{what} '{}' {why}: it becomes a file name, so it must be one plain name (letters, digits, '-', '_', '.')",
            name.escape_debug()
        ),
        None => Ok(()),
    }
}

/// `dir/name`, refusing a `name` that is not one plain file name (see
/// [`check_file_component`]): whatever a config says, output stays in `dir`.
pub fn file_in(dir: &Path, name: &str, what: &str) -> anyhow::Result<PathBuf> {
    check_file_component(name, what)?;
    Ok(dir.join(name))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::{Deserialize, Serialize};

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct T {
        #[serde(with = "bytes")]
        p: PathBuf,
        #[serde(with = "opt_bytes", default)]
        q: Option<PathBuf>,
    }

    #[test]
    fn non_utf8_paths_round_trip_through_bincode() {
        let raw = PathBuf::from(OsString::from_vec(b"/tmp/sc\xe9ne/v.pxo".to_vec()));
        let t = T {
            p: raw.clone(),
            q: Some(raw.join("x")),
        };
        let b = bincode::serde::encode_to_vec(&t, bincode::config::standard()).unwrap();
        let (back, _): (T, usize) =
            bincode::serde::decode_from_slice(&b, bincode::config::standard()).unwrap();
        assert_eq!(back, t);
        let none = T { p: raw, q: None };
        let b = bincode::serde::encode_to_vec(&none, bincode::config::standard()).unwrap();
        let (back, _): (T, usize) =
            bincode::serde::decode_from_slice(&b, bincode::config::standard()).unwrap();
        assert_eq!(back, none);
    }

    #[test]
    fn toml_reads_paths_as_strings() {
        let t: T = toml::from_str("p = \"a/b.pxo\"\nq = \"c\"\n").unwrap();
        assert_eq!(t.p, PathBuf::from("a/b.pxo"));
        assert_eq!(t.q, Some(PathBuf::from("c")));
        let t: T = toml::from_str("p = \"a\"\n").unwrap();
        assert_eq!(t.q, None);
    }

    #[test]
    fn file_components_are_checked() {
        for ok in ["proj-01", "a.b", "é", "p_3"] {
            check_file_component(ok, "id").unwrap();
        }
        for bad in ["", ".", "..", "../../x", "a/b", "a\\b", "a\0b", "a\nb"] {
            let e = check_file_component(bad, "p.toml: id")
                .unwrap_err()
                .to_string();
            assert!(e.contains("p.toml: id"), "{e}");
        }
        assert_eq!(
            file_in(Path::new("/out"), "p1.png", "id").unwrap(),
            Path::new("/out/p1.png")
        );
        assert!(file_in(Path::new("/out"), "../p1.png", "id").is_err());
    }
}
