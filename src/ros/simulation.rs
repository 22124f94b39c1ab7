//! The node as a standard simulator (ROS 2's `simulation_interfaces`), as rules without I/O:
//! which state a request leads to, which result code answers it, what a reset covers, and which
//! features the node advertises. The node (`ros::node`) applies the outcomes to the lines.
//!
//! The node's simulation state covers all its lines at once:
//! - **PAUSED**: lock-step. Each line waits at its tick for the commands that answer it, or for
//!   StepSimulation, which advances every line N ticks on its last valid command (as N ticks of
//!   PLAYING would: a line at its time limit starts a new episode) and replies when all N are done.
//!   The node starts PAUSED with `--mode lockstep`.
//! - **PLAYING**: realtime at `--rate` ticks per second on the last valid commands. The node starts
//!   PLAYING with `--mode realtime`.
//! - **STOPPED**: paused and reset to the start (time and state, as SCOPE_ALL): no tick happens,
//!   commands are rejected (`stopped` on /diagnostics) and StepSimulation answers INCORRECT_STATE.
//!   PLAYING or PAUSED starts it again.
//! - The **SimulateSteps** action steps as StepSimulation does, with feedback (the first step, at most one per
//!   10 ms, the last step: FEEDBACK_PERIOD in `ros::node`); a
//!   cancel ends it after the step in progress. A goal the rules refuse is accepted and ends at
//!   once, aborted, with the refusal's code and reason in its result (a rejected goal could not
//!   say why).
//! - **QUITTING** (set only): the node replies, then leaves the graph as on SIGINT.
//!
//! Reset scopes: STATE puts every line back to how it was built (its seed's random streams from the
//! start, episode 0, the start speed); TIME puts the tick counter, and so the stamps and /clock,
//! back to 0; DEFAULT and ALL are both. SPAWNED is unsupported (the line spawns nothing). While
//! a StepSimulation runs, every other request that changes the simulation answers INCORRECT_STATE.
//!
//! The standard's StepSimulation comment names OPERATION_FAILED for a step while not paused, its
//! Result message names INCORRECT_STATE for exactly that case; we answer INCORRECT_STATE.

use super::options::TickMode;

/// simulation_interfaces/Result codes, and SetSimulationState's own.
pub mod code {
    pub const FEATURE_UNSUPPORTED: u8 = 0;
    pub const OK: u8 = 1;
    pub const NOT_FOUND: u8 = 2;
    pub const INCORRECT_STATE: u8 = 3;
    pub const OPERATION_FAILED: u8 = 4;
    pub const ALREADY_IN_TARGET_STATE: u8 = 101;
    pub const STATE_TRANSITION_ERROR: u8 = 102;
    pub const INCORRECT_TRANSITION: u8 = 103;

    /// The name of a code, for logs and /diagnostics counters.
    pub fn name(code: u8) -> &'static str {
        match code {
            FEATURE_UNSUPPORTED => "feature_unsupported",
            OK => "ok",
            NOT_FOUND => "not_found",
            INCORRECT_STATE => "incorrect_state",
            OPERATION_FAILED => "operation_failed",
            ALREADY_IN_TARGET_STATE => "already_in_target_state",
            STATE_TRANSITION_ERROR => "state_transition_error",
            INCORRECT_TRANSITION => "incorrect_transition",
            _ => "other",
        }
    }

    /// Every code the node answers with other than OK (the /diagnostics counters).
    pub const REFUSALS: [u8; 3] = [FEATURE_UNSUPPORTED, INCORRECT_STATE, ALREADY_IN_TARGET_STATE];
}

/// simulation_interfaces/SimulationState values.
pub mod state {
    pub const STOPPED: u8 = 0;
    pub const PLAYING: u8 = 1;
    pub const PAUSED: u8 = 2;
    pub const QUITTING: u8 = 3;
    pub const NO_WORLD: u8 = 4;
    pub const LOADING_WORLD: u8 = 5;
}

/// simulation_interfaces/ResetSimulation scopes (a bit field).
pub mod scope {
    pub const DEFAULT: u8 = 0;
    pub const TIME: u8 = 1;
    pub const STATE: u8 = 2;
    pub const SPAWNED: u8 = 4;
    pub const ALL: u8 = 255;
}

/// simulation_interfaces/SimulatorFeatures values the node advertises.
pub mod feature {
    pub const SIMULATION_RESET: u16 = 20;
    pub const SIMULATION_RESET_TIME: u16 = 21;
    pub const SIMULATION_RESET_STATE: u16 = 22;
    pub const SIMULATION_STATE_GETTING: u16 = 24;
    pub const SIMULATION_STATE_SETTING: u16 = 25;
    pub const SIMULATION_STATE_PAUSE: u16 = 26;
    pub const STEP_SIMULATION_SINGLE: u16 = 31;
    pub const STEP_SIMULATION_MULTIPLE: u16 = 32;
    pub const STEP_SIMULATION_ACTION: u16 = 33;
}

/// Exactly what works (GetSimulatorFeatures): reset (time, state), getting and setting the state
/// (pause included), stepping once and many times, by service and by the SimulateSteps action.
/// No entities, spawning or worlds.
pub fn features() -> Vec<u16> {
    use feature::*;
    vec![
        SIMULATION_RESET,
        SIMULATION_RESET_TIME,
        SIMULATION_RESET_STATE,
        SIMULATION_STATE_GETTING,
        SIMULATION_STATE_SETTING,
        SIMULATION_STATE_PAUSE,
        STEP_SIMULATION_SINGLE,
        STEP_SIMULATION_MULTIPLE,
        STEP_SIMULATION_ACTION,
    ]
}

/// The node's simulation state (the settable ones; QUITTING ends the node).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimState {
    Stopped,
    Playing,
    Paused,
}

impl SimState {
    /// The state the node starts in: `--mode lockstep` is PAUSED, `--mode realtime` PLAYING.
    pub fn initial(mode: TickMode) -> Self {
        match mode {
            TickMode::Lockstep => SimState::Paused,
            TickMode::Realtime => SimState::Playing,
        }
    }

    /// The standard's value.
    pub fn code(self) -> u8 {
        match self {
            SimState::Stopped => state::STOPPED,
            SimState::Playing => state::PLAYING,
            SimState::Paused => state::PAUSED,
        }
    }

    /// How the lines tick in this state (STOPPED lines do not tick at all: see `halted`).
    pub fn tick_mode(self) -> TickMode {
        match self {
            SimState::Playing => TickMode::Realtime,
            SimState::Paused | SimState::Stopped => TickMode::Lockstep,
        }
    }

    /// Whether the lines are halted: no tick, commands rejected.
    pub fn halted(self) -> bool {
        self == SimState::Stopped
    }

    pub fn name(self) -> &'static str {
        match self {
            SimState::Stopped => "STOPPED",
            SimState::Playing => "PLAYING",
            SimState::Paused => "PAUSED",
        }
    }
}

/// A request the node refuses: the standard's result code and a sentence saying why and what to do.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Refusal {
    pub code: u8,
    pub message: String,
}

fn refuse<T>(code: u8, message: impl Into<String>) -> Result<T, Refusal> {
    Err(Refusal { code, message: message.into() })
}

/// A StepSimulation in progress: (steps done, steps asked).
pub type Stepping = Option<(u64, u64)>;

/// Nothing else may change the simulation while a StepSimulation runs.
fn not_busy(stepping: Stepping) -> Result<(), Refusal> {
    match stepping {
        Some((done, steps)) => refuse(
            code::INCORRECT_STATE,
            format!("a StepSimulation of {steps} steps is in progress ({done} done): wait for its reply"),
        ),
        None => Ok(()),
    }
}

/// What a SetSimulationState request does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transition {
    /// Enter `to`; with `reset`, reset time and state first (stopping).
    To { to: SimState, reset: bool },
    /// Reply, then leave the graph.
    Quit,
}

/// SetSimulationState from `current` to the standard's state value `target`.
pub fn transition(current: SimState, target: u8, stepping: Stepping) -> Result<Transition, Refusal> {
    not_busy(stepping)?;
    let to = match target {
        state::STOPPED => SimState::Stopped,
        state::PLAYING => SimState::Playing,
        state::PAUSED => SimState::Paused,
        state::QUITTING => return Ok(Transition::Quit),
        state::NO_WORLD | state::LOADING_WORLD => {
            return refuse(
                code::FEATURE_UNSUPPORTED,
                format!("state {target} (NO_WORLD / LOADING_WORLD): the node has one line setup, chosen at start, and no worlds to unload or load"),
            )
        }
        _ => {
            return refuse(
                code::FEATURE_UNSUPPORTED,
                format!("state {target} is not a SimulationState: allowed 0 STOPPED, 1 PLAYING, 2 PAUSED, 3 QUITTING"),
            )
        }
    };
    if to == current {
        return refuse(code::ALREADY_IN_TARGET_STATE, format!("the simulation is already {}", to.name()));
    }
    Ok(Transition::To { to, reset: to == SimState::Stopped })
}

/// What a ResetSimulation covers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ResetScope {
    /// Ticks (stamps, /clock) back to 0.
    pub time: bool,
    /// Every line back to how it was built.
    pub state: bool,
}

impl ResetScope {
    pub const ALL: ResetScope = ResetScope { time: true, state: true };
}

/// ResetSimulation with the standard's `scope` bit field.
pub fn reset_scope(scope: u8, stepping: Stepping) -> Result<ResetScope, Refusal> {
    not_busy(stepping)?;
    match scope {
        scope::DEFAULT | scope::ALL => Ok(ResetScope::ALL),
        s if s & !(scope::TIME | scope::STATE) != 0 => refuse(
            code::FEATURE_UNSUPPORTED,
            format!(
                "scope {s} is not supported: the line spawns nothing (SPAWNED, 4) and has no other scope; allowed \
                 0 DEFAULT, 1 TIME, 2 STATE, 3 TIME|STATE, 255 ALL"
            ),
        ),
        s => Ok(ResetScope { time: s & scope::TIME != 0, state: s & scope::STATE != 0 }),
    }
}

/// StepSimulation of `steps` in `current`: the number of steps to run (0 answers at once).
pub fn step_request(current: SimState, steps: u64, stepping: Stepping) -> Result<u64, Refusal> {
    not_busy(stepping)?;
    if current != SimState::Paused {
        return refuse(
            code::INCORRECT_STATE,
            format!(
                "the simulation is {}: StepSimulation needs it PAUSED (SetSimulationState to 2 first)",
                current.name()
            ),
        );
    }
    Ok(steps)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_start_mode_is_the_start_state() {
        assert_eq!(SimState::initial(TickMode::Lockstep), SimState::Paused);
        assert_eq!(SimState::initial(TickMode::Realtime), SimState::Playing);
        assert_eq!(SimState::Playing.tick_mode(), TickMode::Realtime);
        assert!(SimState::Stopped.halted() && !SimState::Paused.halted());
    }

    #[test]
    fn transitions_follow_the_standard() {
        use SimState::*;
        for from in [Stopped, Playing, Paused] {
            for to in [Stopped, Playing, Paused] {
                let got = transition(from, to.code(), None);
                if from == to {
                    assert_eq!(got.unwrap_err().code, code::ALREADY_IN_TARGET_STATE, "{from:?} -> {to:?}");
                } else {
                    assert_eq!(got, Ok(Transition::To { to, reset: to == Stopped }), "{from:?} -> {to:?}");
                }
            }
            assert_eq!(transition(from, state::QUITTING, None), Ok(Transition::Quit));
            for target in [state::NO_WORLD, state::LOADING_WORLD, 6, 255] {
                let refusal = transition(from, target, None).unwrap_err();
                assert_eq!(refusal.code, code::FEATURE_UNSUPPORTED, "{target}");
                assert!(refusal.message.starts_with(&format!("state {target} ")), "{}", refusal.message);
            }
        }
        let busy = transition(Paused, state::PLAYING, Some((3, 50))).unwrap_err();
        assert_eq!(busy.code, code::INCORRECT_STATE);
        assert!(busy.message.contains("StepSimulation of 50 steps is in progress (3 done)"), "{}", busy.message);
    }

    #[test]
    fn reset_scopes_are_time_and_state_only() {
        let scope = |time, state| Ok(ResetScope { time, state });
        assert_eq!(reset_scope(scope::DEFAULT, None), scope(true, true));
        assert_eq!(reset_scope(scope::ALL, None), scope(true, true));
        assert_eq!(reset_scope(scope::TIME, None), scope(true, false));
        assert_eq!(reset_scope(scope::STATE, None), scope(false, true));
        assert_eq!(reset_scope(scope::TIME | scope::STATE, None), scope(true, true));
        for unsupported in [scope::SPAWNED, scope::SPAWNED | scope::STATE, 8, 128, 254] {
            let refusal = reset_scope(unsupported, None).unwrap_err();
            assert_eq!(refusal.code, code::FEATURE_UNSUPPORTED, "{unsupported}");
            assert!(refusal.message.contains("allowed 0 DEFAULT, 1 TIME, 2 STATE, 3 TIME|STATE, 255 ALL"));
        }
        assert_eq!(reset_scope(scope::ALL, Some((0, 1))).unwrap_err().code, code::INCORRECT_STATE);
    }

    #[test]
    fn steps_only_when_paused_and_idle() {
        assert_eq!(step_request(SimState::Paused, 50, None), Ok(50));
        assert_eq!(step_request(SimState::Paused, 0, None), Ok(0));
        for other in [SimState::Playing, SimState::Stopped] {
            let refusal = step_request(other, 1, None).unwrap_err();
            assert_eq!(refusal.code, code::INCORRECT_STATE);
            assert!(refusal.message.contains(&format!("is {}: StepSimulation needs it PAUSED", other.name())));
        }
        assert_eq!(step_request(SimState::Paused, 1, Some((1, 2))).unwrap_err().code, code::INCORRECT_STATE);
    }

    #[test]
    fn features_are_what_the_node_serves() {
        let f = features();
        assert!(f.contains(&feature::SIMULATION_STATE_PAUSE) && f.contains(&feature::STEP_SIMULATION_ACTION));
        // Not advertised: SIMULATION_RESET_SPAWNED (23), entities, worlds.
        assert!(f.iter().all(|&x| !matches!(x, 0..=14 | 23 | 40..=50)), "{f:?}");
    }
}
