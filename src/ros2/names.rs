//! ROS 2 names (`/polymap/leju/map_updates`), checked once, and the Zenoh keys each wire
//! convention makes of them.

use std::fmt;

/// A fully qualified ROS 2 topic or service name: `/` then tokens of letters, digits and
/// underscores (not starting with a digit), separated by single `/`.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct RosName(String);

impl RosName {
    pub fn parse(name: &str) -> Result<RosName, String> {
        let Some(rest) = name.strip_prefix('/') else {
            return Err(format!("{name:?} is not a fully qualified ROS name (it must start with '/')"));
        };
        if rest.is_empty() {
            return Err("\"/\" names nothing".into());
        }
        for token in rest.split('/') {
            let ok = token.chars().next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
                && token.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
            if !ok {
                return Err(format!(
                    "{name:?} is not a ROS name: each part between '/' must be letters, digits and '_', not starting with a digit (got {token:?})"
                ));
            }
        }
        Ok(RosName(name.to_string()))
    }

    /// The root namespace, `/` (a namespace, never a topic's name).
    pub fn root() -> RosName {
        RosName("/".into())
    }

    /// `self` followed by the relative name `child` (`/polymap/leju` + `map_updates`).
    pub fn join(&self, child: &str) -> Result<RosName, String> {
        RosName::parse(&format!("{}/{child}", self.0.trim_end_matches('/')))
    }

    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Without the leading `/`: the Zenoh key's chunks.
    pub fn stripped(&self) -> &str {
        &self.0[1..]
    }

    /// Every `/` as `%`: rmw_zenoh's form of a name inside a liveliness token.
    pub fn mangled(&self) -> String {
        self.0.replace('/', "%")
    }
}

impl fmt::Display for RosName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl serde::Serialize for RosName {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.0)
    }
}

impl<'de> serde::Deserialize<'de> for RosName {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<RosName, D::Error> {
        let s = String::deserialize(d)?;
        RosName::parse(&s).map_err(serde::de::Error::custom)
    }
}
