//! The DDS participant, set up from ROS 2 Jazzy's discovery environment as rcl reads it and
//! rmw_fastrtps (Jazzy's default middleware) applies it, so the node joins the same graphs an
//! rclpy node in the same shell joins:
//!
//! - `ROS_DOMAIN_ID` (0 when unset): the DDS domain.
//! - `ROS_AUTOMATIC_DISCOVERY_RANGE`: `SUBNET` (the default) multicast discovery on every
//!   interface; `LOCALHOST` no multicast, discovery only of participants on this host (and of
//!   the static peers), and nothing sent anywhere else, whatever other participants advertise
//!   (RustDDS `localhost_only`, see vendor/README.md); `OFF` no discovery; `SYSTEM_DEFAULT`
//!   the DDS implementation's own defaults (for RustDDS the same as SUBNET), static peers
//!   ignored.
//! - `ROS_STATIC_PEERS`: `;`-separated addresses or host names that discovery is also sent to
//!   by unicast (with SUBNET and LOCALHOST).
//! - `ROS_LOCALHOST_ONLY=1` (deprecated): LOCALHOST, the other two ignored, with rcl's warnings.
//!
//! Unlike rcl, which warns and falls back to LOCALHOST, a value outside these fails at start
//! with the variable, the value and what is allowed (a typo must not silently change which
//! machines the simulator talks to). OFF is as close as RustDDS gets: the node announces
//! itself to nobody, advertises only loopback and sends only on this host, but RustDDS cannot
//! ignore a same-host participant that announces itself to the node's discovery port (Fast DDS
//! under OFF runs no discovery at all).

use std::net::{IpAddr, Ipv4Addr, ToSocketAddrs};
use std::sync::Arc;

use rustdds::{DomainParticipant, DomainParticipantBuilder};

use super::type_hash::endpoint_user_data;

/// Highest ROS_DOMAIN_ID DDS allows with the default port mapping.
pub const MAX_DOMAIN_ID: u16 = 232;

/// How far automatic discovery reaches (`ROS_AUTOMATIC_DISCOVERY_RANGE`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Range {
    Subnet,
    Localhost,
    Off,
    SystemDefault,
}

impl Range {
    const NAMES: [(&'static str, Range); 4] = [
        ("SUBNET", Range::Subnet),
        ("LOCALHOST", Range::Localhost),
        ("OFF", Range::Off),
        ("SYSTEM_DEFAULT", Range::SystemDefault),
    ];

    fn name(self) -> &'static str {
        Self::NAMES.iter().find(|(_, r)| *r == self).map(|(n, _)| *n).unwrap_or_default()
    }
}

/// The discovery settings of the environment, validated.
#[derive(Clone, Debug, PartialEq)]
pub struct Discovery {
    pub domain: u16,
    pub range: Range,
    /// Resolved addresses of `ROS_STATIC_PEERS` (empty where the range ignores them).
    pub static_peers: Vec<IpAddr>,
    /// What rcl would warn about (deprecated or ignored settings).
    pub warnings: Vec<String>,
}

impl Discovery {
    /// From the process environment.
    pub fn from_env() -> Result<Self, String> {
        Self::from_vars(|name| std::env::var(name).ok())
    }

    /// From variables looked up by `var` (unset and empty are the same, as in rcl).
    pub fn from_vars(var: impl Fn(&str) -> Option<String>) -> Result<Self, String> {
        let var = |name: &str| var(name).filter(|v| !v.is_empty());
        let domain = match var("ROS_DOMAIN_ID") {
            None => 0,
            Some(v) => v
                .trim()
                .parse::<u16>()
                .ok()
                .filter(|d| *d <= MAX_DOMAIN_ID)
                .ok_or_else(|| format!("ROS_DOMAIN_ID = {v} is out of range: allowed 0 ..= {MAX_DOMAIN_ID}"))?,
        };
        let mut range = match var("ROS_AUTOMATIC_DISCOVERY_RANGE") {
            None => Range::Subnet,
            Some(v) => Range::NAMES.iter().find(|(n, _)| *n == v).map(|(_, r)| *r).ok_or_else(|| {
                let allowed: Vec<&str> = Range::NAMES.iter().map(|(n, _)| *n).collect();
                format!(
                    "ROS_AUTOMATIC_DISCOVERY_RANGE = {v} is not valid: allowed {} (or unset: SUBNET)",
                    allowed.join(", ")
                )
            })?,
        };
        let peers = var("ROS_STATIC_PEERS").unwrap_or_default();
        let mut peers: Vec<&str> = peers.split(';').map(str::trim).filter(|p| !p.is_empty()).collect();
        let mut warnings = Vec::new();
        if var("ROS_LOCALHOST_ONLY").as_deref() == Some("1") {
            warnings.push(
                "ROS_LOCALHOST_ONLY is deprecated but still honored if it is enabled. Use ROS_AUTOMATIC_DISCOVERY_RANGE \
                 and ROS_STATIC_PEERS instead."
                    .to_string(),
            );
            warnings.push(
                "'localhost_only' is enabled, 'automatic_discovery_range' and 'static_peers' will be ignored."
                    .to_string(),
            );
            range = Range::Localhost;
            peers.clear();
        }
        if !peers.is_empty() && matches!(range, Range::Off | Range::SystemDefault) {
            warnings.push(format!("ROS_STATIC_PEERS is ignored with ROS_AUTOMATIC_DISCOVERY_RANGE = {}", range.name()));
            peers.clear();
        }
        let static_peers = peers.iter().map(|p| resolve(p)).collect::<Result<_, _>>()?;
        Ok(Discovery { domain, range, static_peers, warnings })
    }

    /// The builder of a participant that discovers as configured, with every endpoint announcing
    /// its type hash.
    pub fn participant_builder(&self) -> DomainParticipantBuilder {
        let builder = DomainParticipantBuilder::new(self.domain).with_endpoint_user_data(Arc::new(endpoint_user_data));
        match self.range {
            Range::Subnet => builder.with_static_peers(self.static_peers.clone()),
            // Traffic stays on this host but for the static peers, which are also the only reason
            // to advertise more than loopback.
            Range::Localhost => {
                let builder =
                    builder.multicast(false).localhost_only(true).with_static_peers(self.static_peers.clone());
                if self.static_peers.is_empty() {
                    builder.with_only_networks([Ipv4Addr::LOCALHOST])
                } else {
                    builder
                }
            }
            Range::Off => builder
                .multicast(false)
                .localhost_only(true)
                .same_host_loopback(false)
                .with_only_networks([Ipv4Addr::LOCALHOST]),
            Range::SystemDefault => builder,
        }
    }

    /// Builds the participant.
    pub fn participant(&self) -> Result<DomainParticipant, String> {
        self.participant_builder()
            .build()
            .map_err(|e| format!("cannot create the DDS participant on domain {}: {e:?}", self.domain))
    }

    /// For the start-up log line.
    pub fn summary(&self) -> String {
        let peers: Vec<String> = self.static_peers.iter().map(IpAddr::to_string).collect();
        let peers = if peers.is_empty() { String::new() } else { format!(", static peers {}", peers.join(";")) };
        format!("ROS_DOMAIN_ID {}, discovery range {}{peers}", self.domain, self.range.name())
    }
}

/// The first IPv4 address of a peer (rmw_fastrtps takes the first IPv4 one too).
fn resolve(peer: &str) -> Result<IpAddr, String> {
    let bad = |why: String| {
        format!("ROS_STATIC_PEERS: peer '{peer}' {why}: allowed IPv4 addresses or host names, separated by ';'")
    };
    if let Ok(ip) = peer.parse::<IpAddr>() {
        return if ip.is_ipv4() { Ok(ip) } else { Err(bad("is IPv6".into())) };
    }
    let addrs = (peer, 0).to_socket_addrs().map_err(|e| bad(format!("cannot be resolved ({e})")))?;
    addrs.map(|a| a.ip()).find(IpAddr::is_ipv4).ok_or_else(|| bad("has no IPv4 address".into()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn from(vars: &[(&str, &str)]) -> Result<Discovery, String> {
        let vars: Vec<(String, String)> = vars.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        Discovery::from_vars(|name| vars.iter().find(|(k, _)| k == name).map(|(_, v)| v.clone()))
    }

    #[test]
    fn defaults_are_rcls() {
        let d = from(&[]).unwrap();
        assert_eq!((d.domain, d.range, d.static_peers.len(), d.warnings.len()), (0, Range::Subnet, 0, 0));
        let d = from(&[("ROS_DOMAIN_ID", ""), ("ROS_AUTOMATIC_DISCOVERY_RANGE", "")]).unwrap();
        assert_eq!((d.domain, d.range), (0, Range::Subnet));
    }

    #[test]
    fn every_range_and_static_peers() {
        for (name, range) in Range::NAMES {
            assert_eq!(from(&[("ROS_AUTOMATIC_DISCOVERY_RANGE", name)]).unwrap().range, range);
        }
        let d = from(&[("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST"), ("ROS_STATIC_PEERS", "10.0.0.2; localhost;;")])
            .unwrap();
        assert_eq!(d.static_peers, vec![IpAddr::from([10, 0, 0, 2]), IpAddr::from([127, 0, 0, 1])]);
        let d = from(&[("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF"), ("ROS_STATIC_PEERS", "10.0.0.2")]).unwrap();
        assert!(d.static_peers.is_empty() && d.warnings[0].contains("ignored"), "{d:?}");
    }

    #[test]
    fn localhost_only_is_localhost_without_peers() {
        let d = from(&[
            ("ROS_LOCALHOST_ONLY", "1"),
            ("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET"),
            ("ROS_STATIC_PEERS", "10.0.0.2"),
        ])
        .unwrap();
        assert_eq!((d.range, d.static_peers.len()), (Range::Localhost, 0));
        assert!(d.warnings[0].contains("ROS_LOCALHOST_ONLY is deprecated"), "{d:?}");
        assert_eq!(from(&[("ROS_LOCALHOST_ONLY", "0")]).unwrap().range, Range::Subnet);
    }

    #[test]
    fn bad_values_name_variable_value_and_allowed() {
        let e = from(&[("ROS_AUTOMATIC_DISCOVERY_RANGE", "localhost")]).unwrap_err();
        assert!(e.contains("ROS_AUTOMATIC_DISCOVERY_RANGE = localhost is not valid: allowed SUBNET, LOCALHOST, OFF, SYSTEM_DEFAULT"), "{e}");
        let e = from(&[("ROS_DOMAIN_ID", "233")]).unwrap_err();
        assert!(e.contains("ROS_DOMAIN_ID = 233 is out of range: allowed 0 ..= 232"), "{e}");
        let e = from(&[("ROS_STATIC_PEERS", "::1")]).unwrap_err();
        assert!(e.contains("ROS_STATIC_PEERS: peer '::1' is IPv6"), "{e}");
        // (No unresolvable host name here: the lookup could leave the machine.)
    }
}
