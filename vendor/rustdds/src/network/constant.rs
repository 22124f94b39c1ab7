// These constants are from RTPS spec Section 9.6.2.3 Default Port Numbers
const PB: u16 = 7400;
const DG: u16 = 250;
const PG: u16 = 2;

const D0: u16 = 0;
const D1: u16 = 10;
const D2: u16 = 1;
const D3: u16 = 11;

pub const fn spdp_well_known_multicast_port(domain_id: u16) -> u16 {
  PB + DG * domain_id + D0
}

pub const fn spdp_well_known_unicast_port(domain_id: u16, participant_id: u16) -> u16 {
  PB + DG * domain_id + D1 + PG * participant_id
}

pub const fn user_traffic_multicast_port(domain_id: u16) -> u16 {
  PB + DG * domain_id + D2
}

pub const fn user_traffic_unicast_port(domain_id: u16, participant_id: u16) -> u16 {
  PB + DG * domain_id + D3 + PG * participant_id
}

/// [sorting_line patch] The participant ids a participant may take on one host,
/// `0..MAX_PARTICIPANT_ID` (the bound rustdds always searched its own id in; RTPS
/// 2.5, 9.6.2.3), less those whose ports leave the 16-bit range: see
/// [`participant_id_count`].
pub const MAX_PARTICIPANT_ID: u16 = 120;

/// [sorting_line patch] How many participant ids domain `domain_id` has on one
/// host: [`MAX_PARTICIPANT_ID`], or fewer where the ports of the higher ids do not
/// fit in 16 bits (63 in domain 232, the highest ROS 2 allows; none from 233 up).
///
/// Same-host SPDP ("localhost peers") is sent to
/// `127.0.0.1:spdp_well_known_unicast_port(domain, pid)` for every `pid` below
/// this, so that two participants on the same host discover each other even
/// when there is no external network and multicast on the loopback interface is
/// unavailable (the Linux default for `lo`); see
/// `src/rtps/loopback_same_host_design.md`. Upstream sent to the first 12 ids
/// only: a peer whose id was 12 or more (a ROS 2 daemon started while a dozen
/// participants ran) never heard us, and found us only if our id was within its
/// own probe range (Fast DDS under ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
/// reached ids up to 31 here), so a node beyond that was never listed.
pub const fn participant_id_count(domain_id: u16) -> u16 {
  // The higher of an id's two unicast ports is its user-traffic port (D3).
  let base = PB as u32 + DG as u32 * domain_id as u32 + D3 as u32;
  if base > u16::MAX as u32 {
    return 0;
  }
  let fitting = (u16::MAX as u32 - base) / PG as u32 + 1;
  if fitting < MAX_PARTICIPANT_ID as u32 {
    fitting as u16
  } else {
    MAX_PARTICIPANT_ID
  }
}

#[cfg(test)]
mod tests {
  use super::*;

  // [sorting_line patch] Every id counted has both ports in range; the next one would not.
  #[test]
  fn participant_ids_have_ports_in_range() {
    for domain in 0..=250u16 {
      let n = participant_id_count(domain);
      if n > 0 {
        let last = PB as u32 + DG as u32 * domain as u32 + D3 as u32 + PG as u32 * (n as u32 - 1);
        assert!(last <= u16::MAX as u32, "domain {domain}: id {} has port {last}", n - 1);
      }
      if n < MAX_PARTICIPANT_ID {
        let next = PB as u32 + DG as u32 * domain as u32 + D3 as u32 + PG as u32 * n as u32;
        assert!(next > u16::MAX as u32, "domain {domain}: id {n} would fit (port {next})");
      }
    }
    assert_eq!(participant_id_count(0), MAX_PARTICIPANT_ID);
    assert_eq!(participant_id_count(199), MAX_PARTICIPANT_ID);
    assert_eq!(participant_id_count(232), 63);
  }
}
