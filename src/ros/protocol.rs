//! The command protocol of one hosted line, without any DDS: which commands a tick needs, which
//! are stale, duplicated, early or invalid, and when the line advances. Keeping it free of I/O
//! lets the unit tests (protocol/tests.rs) pin every rule; the node (`ros::node`) only moves messages
//! in and out.
//!
//! - Lock-step: the line waits at tick T (stamp T * period). A command answers T by carrying that
//!   stamp. When the commands the tick needs have arrived (speed; and sort mode on the advanced
//!   line), the line steps once to T + 1. A second command of the same kind for T is a duplicate;
//!   an older stamp is stale; a newer one names a tick that does not exist yet.
//! - Realtime: a timer steps the line; the newest valid command is held until replaced. Stamps
//!   may lag (the controller answers a tick the line has already left) but may not run ahead or
//!   go backwards.
//!
//! In both modes an invalid value (NaN, off the ten speeds, unknown mode) is rejected and the line
//! keeps its last valid command.
//!
//! An evolving line (one with an evolution schedule) takes the advanced commands whatever its
//! variant, because its hardware comes and goes: while its machine has no sort modes (before the
//! machine upgrade, [`Line::sort_modes_at_next_step`]) a tick needs only the speed, mode 0 is
//! accepted and does nothing, and modes 1 and 2 are rejected ([`Rejection::SortModesOff`]); with
//! modes, a tick needs both commands, as on the advanced line. Every rejection carries a [`Rejection`] reason for the logs and
//! /diagnostics.
//!
//! One client drives a line per episode: the first client ([`Client`], the DDS participant of the
//! command's writer) whose command is accepted in an episode owns the line until the episode ends
//! (a reset, or a realtime line's own restart); commands of any other client are rejected
//! ([`Rejection::NotOwner`]). Two clients can therefore never interleave commands on one line
//! silently, while a client that died is replaced by anyone who resets the line (its stale DDS
//! endpoints may linger for a minute, so the rule cannot wait for them to disappear). Who resets
//! does not matter: a test may reset a line that a controller process then drives.
//!
//! The batch topics carry every line at once. A `batch/cmd` whose lists do not all have one entry
//! per line (modes may be empty on the basic line) is malformed and no line sees any of it;
//! otherwise each line's entry goes through that line's rules above, exactly as if it had come on
//! the line's own topics (sort mode first, then speed). A `batch/reset` must name each line at
//! most once, with one seed flag and one seed per line, or it is refused as a whole.
//! [`batch_commands`] and [`batch_resets`] are those rules.

use std::fmt;

use super::clock::SimClock;
use super::messages::{LineCommands, ResetLinesRequest, Time};
use super::options::TickMode;
use crate::sim::evolution::{category_code, Schedule};
use crate::sim::material::SORT_MODES;
use crate::sim::speed::{index_of_speed, SPEEDS, START_SPEED_INDEX};
use crate::sim::{Action, Line, LineConfig, Observation, SortMode, StepOutcome, Variant};

/// Why a command was dropped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Rejection {
    /// NaN, infinite, out of 0.1..=1.0 or between two of the ten speeds.
    InvalidSpeed,
    /// A sort mode other than 0, 1, 2.
    UnknownMode,
    /// A sort mode sent to the basic line, which has none.
    ModeOnBasicLine,
    /// The stamp names a tick the line has already left.
    Stale,
    /// A second command of the same kind for the same tick.
    Duplicate,
    /// The stamp names a tick that does not exist (yet), or falls between ticks.
    UnknownTick,
    /// The episode reached its time limit: the line waits for a reset.
    EpisodeOver,
    /// The message could not be decoded (wrong type or corrupt data).
    Malformed,
    /// Another client's commands drive this episode of the line.
    NotOwner,
    /// A sort mode other than 0 while the evolving line's machine has no sort modes.
    SortModesOff,
    /// The simulation is STOPPED (simulation_interfaces): no tick happens until it plays or pauses.
    Stopped,
}

pub const REJECTIONS: [Rejection; 11] = [
    Rejection::InvalidSpeed,
    Rejection::UnknownMode,
    Rejection::ModeOnBasicLine,
    Rejection::Stale,
    Rejection::Duplicate,
    Rejection::UnknownTick,
    Rejection::EpisodeOver,
    Rejection::Malformed,
    Rejection::NotOwner,
    Rejection::SortModesOff,
    Rejection::Stopped,
];

impl Rejection {
    /// The counter's name on /diagnostics.
    pub fn key(self) -> &'static str {
        match self {
            Rejection::InvalidSpeed => "invalid_speed",
            Rejection::UnknownMode => "unknown_mode",
            Rejection::ModeOnBasicLine => "mode_on_basic_line",
            Rejection::Stale => "stale",
            Rejection::Duplicate => "duplicate",
            Rejection::UnknownTick => "unknown_tick",
            Rejection::EpisodeOver => "episode_over",
            Rejection::Malformed => "malformed",
            Rejection::NotOwner => "not_owner",
            Rejection::SortModesOff => "sort_modes_off",
            Rejection::Stopped => "stopped",
        }
    }

    /// A sentence for the log. The speeds and the modes' numbers and names are the library's
    /// (`SPEEDS`; `SORT_MODES` by the names serde gives them, which their labels start with).
    pub fn explain(self) -> String {
        let text = match self {
            Rejection::InvalidSpeed => {
                let (first, second, last) = (SPEEDS[0], SPEEDS[1], SPEEDS[SPEEDS.len() - 1]);
                return format!("speed is not one of {first:?}, {second:?}, ..., {last:?}");
            }
            Rejection::UnknownMode => {
                let named: Vec<String> =
                    SORT_MODES.iter().map(|&m| format!("{} ({})", m.index(), mode_name(m))).collect();
                let (last, rest) = named.split_last().expect("the line has sort modes");
                return format!("sort mode is not {} or {last}", rest.join(", "));
            }
            Rejection::ModeOnBasicLine => "the basic line has no sort mode",
            Rejection::Stale => "stamp names a tick the line has already left",
            Rejection::Duplicate => "a command of this kind already answered this tick",
            Rejection::UnknownTick => "stamp names no current tick (ahead of the line or between ticks)",
            Rejection::EpisodeOver => "the episode is over; call reset",
            Rejection::Malformed => "it could not be decoded",
            Rejection::NotOwner => {
                "another client drives this episode of the line (one client per episode; a reset frees the line)"
            }
            Rejection::SortModesOff => {
                "the sorting machine has no sort modes now (before its machine upgrade): only mode 0 is valid"
            }
            Rejection::Stopped => "the simulation is STOPPED; set it to PAUSED or PLAYING (~/set_simulation_state)",
        };
        text.to_string()
    }
}

/// A sort mode's name as `trace` and parameter files write it (its serde name).
fn mode_name(mode: SortMode) -> String {
    serde_json::to_value(mode).ok().and_then(|v| v.as_str().map(str::to_owned)).unwrap_or_default()
}

/// Who sent a command: the GUID prefix of its DDS writer, i.e. the sending participant (one rclpy
/// context, or one process of ros2-client). Opaque to the protocol: only compared.
pub type Client = [u8; 12];

/// What one command asks of a line (its stamp and sender travel beside it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command {
    /// `cmd/speed`: a belt speed, one of 0.1, ..., 1.0.
    Speed(f64),
    /// `cmd/sort_mode`: 0 basic, 1 positive, 2 negative (advanced line).
    Mode(u8),
}

impl fmt::Display for Command {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Command::Speed(speed) => write!(f, "speed {speed}"),
            Command::Mode(mode) => write!(f, "sort mode {mode}"),
        }
    }
}

/// Indices of the per-kind realtime watermarks.
const SPEED: usize = 0;
const MODE: usize = 1;

/// What a command did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Accepted {
    /// Stored; the tick still waits for another command (lock-step) or for the timer (realtime).
    Stored,
    /// It completed the tick: the line stepped.
    Stepped(StepOutcome),
}

/// One line as the node hosts it.
#[derive(Clone, Debug)]
pub struct HostedLine {
    line: Line,
    clock: SimClock,
    mode: TickMode,
    /// Tick number of the current state; runs on across episodes.
    tick: u64,
    pending_speed: Option<usize>,
    pending_mode: Option<SortMode>,
    /// The last valid command (realtime holds it; lock-step reports it).
    held: Action,
    /// Newest stamp accepted in realtime mode, per kind (speed, mode): the two commands of one
    /// tick may arrive in either order, so one kind must not make the other's stamp stale.
    newest_stamp: [i64; 2],
    /// The client whose command was accepted first in this episode; None until then.
    owner: Option<Client>,
    /// The simulation is STOPPED: every command is rejected.
    halted: bool,
    /// What the line was built from, for a reset of the simulation's state.
    start: (LineConfig, u64),
}

impl HostedLine {
    pub fn new(config: LineConfig, seed: u64, clock: SimClock, mode: TickMode) -> Self {
        Self::with_evolution(config, seed, Schedule::default(), clock, mode)
    }

    /// A hosted line that evolves by `schedule` (see the module docs for its commands).
    pub fn with_evolution(config: LineConfig, seed: u64, schedule: Schedule, clock: SimClock, mode: TickMode) -> Self {
        HostedLine {
            start: (config.clone(), seed),
            halted: false,
            line: Line::with_evolution(config, seed, schedule),
            clock,
            mode,
            tick: 0,
            pending_speed: None,
            pending_mode: None,
            held: Action::new(START_SPEED_INDEX, SortMode::Basic),
            newest_stamp: [i64::MIN; 2],
            owner: None,
        }
    }

    pub fn line(&self) -> &Line {
        &self.line
    }
    pub fn tick(&self) -> u64 {
        self.tick
    }
    pub fn stamp(&self) -> Time {
        self.clock.stamp(self.tick)
    }
    /// The client driving this episode, if any command has been accepted in it.
    pub fn owner(&self) -> Option<Client> {
        self.owner
    }

    /// How the line ticks now (the simulation's state decides: PLAYING is realtime).
    pub fn mode(&self) -> TickMode {
        self.mode
    }

    /// Switches between lock-step and realtime. Entering lock-step, the current tick waits for
    /// commands stamped with it: a command a realtime line held for its next timer tick does not
    /// answer it.
    pub fn set_mode(&mut self, mode: TickMode) {
        if mode == TickMode::Lockstep {
            self.pending_speed = None;
            self.pending_mode = None;
        }
        self.mode = mode;
    }

    /// STOPPED (true): every command is rejected until the simulation plays or pauses again.
    pub fn set_halted(&mut self, halted: bool) {
        self.halted = halted;
    }

    /// The line as it was built: its seed's random streams from the start, episode 0, the start
    /// speed, no owner. The tick counter runs on (see [`Self::rewind_time`]).
    pub fn restart(&mut self) -> Observation {
        let (config, seed) = self.start.clone();
        self.line = Line::with_evolution(config, seed, self.line.evolution().clone());
        self.clear_episode();
        self.tick += 1;
        self.line.observation()
    }

    /// The tick counter, and so the stamps, back to 0. Commands stamped before are stale or name
    /// ticks that do not exist (yet); realtime watermarks start again.
    pub fn rewind_time(&mut self) {
        self.tick = 0;
        self.pending_speed = None;
        self.pending_mode = None;
        self.newest_stamp = [i64::MIN; 2];
    }

    fn clear_episode(&mut self) {
        self.pending_speed = None;
        self.pending_mode = None;
        self.held = Action::new(START_SPEED_INDEX, SortMode::Basic);
        self.owner = None;
    }

    fn advanced(&self) -> bool {
        self.line.config().variant == Variant::Advanced
    }

    /// The category the line's observation reports on the wire: the true category of the next
    /// batch on a line without a schedule (as the basic line has always carried it), the ratio
    /// sensor's reading on an evolving line (3, unknown, while it has no ratio sensor).
    pub fn category_reading(&self) -> u8 {
        if self.evolving() {
            category_code(self.line.category_reading())
        } else {
            self.line.observation().category as u8
        }
    }

    /// Whether the line has an evolution schedule.
    pub fn evolving(&self) -> bool {
        !self.line.evolution().is_empty()
    }

    /// Whether the tick the line waits at takes (and in lock-step needs) a sort mode command.
    pub fn takes_modes(&self) -> bool {
        if self.evolving() {
            self.line.sort_modes_at_next_step()
        } else {
            self.advanced()
        }
    }

    /// Starts a new episode at a new tick (stamps never repeat, so old commands become stale).
    pub fn reset(&mut self, seed: Option<u64>) -> Observation {
        self.tick += 1;
        self.clear_episode();
        self.line.reset(seed)
    }

    /// `cmd/speed` from a client: refused unless it owns the episode or nobody does yet; the first
    /// accepted command of an episode makes its client the owner.
    pub fn speed_from(&mut self, client: Client, stamp: Time, speed: f64) -> Result<Accepted, Rejection> {
        self.admit(client)?;
        self.on_speed(stamp, speed).inspect(|_| self.owner = Some(client))
    }

    /// `cmd/sort_mode` from a client, under the same ownership rule as [`Self::speed_from`].
    pub fn sort_mode_from(&mut self, client: Client, stamp: Time, mode: u8) -> Result<Accepted, Rejection> {
        self.admit(client)?;
        self.on_sort_mode(stamp, mode).inspect(|_| self.owner = Some(client))
    }

    /// A command from a client: [`Self::speed_from`] or [`Self::sort_mode_from`].
    pub fn command_from(&mut self, client: Client, stamp: Time, command: Command) -> Result<Accepted, Rejection> {
        match command {
            Command::Speed(speed) => self.speed_from(client, stamp, speed),
            Command::Mode(mode) => self.sort_mode_from(client, stamp, mode),
        }
    }

    fn admit(&self, client: Client) -> Result<(), Rejection> {
        if self.halted {
            return Err(Rejection::Stopped);
        }
        match self.owner {
            Some(owner) if owner != client => Err(Rejection::NotOwner),
            _ => Ok(()),
        }
    }

    /// Handles `cmd/speed`.
    pub fn on_speed(&mut self, stamp: Time, speed: f64) -> Result<Accepted, Rejection> {
        let index = index_of_speed(speed).ok_or(Rejection::InvalidSpeed)?;
        self.check_stamp(stamp, self.pending_speed.is_some(), SPEED)?;
        self.held.speed_index = index;
        self.pending_speed = Some(index);
        Ok(self.complete_tick())
    }

    /// Handles `cmd/sort_mode`.
    pub fn on_sort_mode(&mut self, stamp: Time, mode: u8) -> Result<Accepted, Rejection> {
        if !self.advanced() && !self.evolving() {
            return Err(Rejection::ModeOnBasicLine);
        }
        let mode = SortMode::from_index(mode).ok_or(Rejection::UnknownMode)?;
        if mode != SortMode::Basic && !self.takes_modes() {
            return Err(Rejection::SortModesOff);
        }
        self.check_stamp(stamp, self.pending_mode.is_some(), MODE)?;
        self.held.mode = mode;
        self.pending_mode = Some(mode);
        Ok(self.complete_tick())
    }

    fn check_stamp(&mut self, stamp: Time, already_answered: bool, kind: usize) -> Result<(), Rejection> {
        // Not a valid ROS time, and it would alias another stamp (sec - 1, nanosec + 1e9).
        if stamp.nanosec >= 1_000_000_000 {
            return Err(Rejection::UnknownTick);
        }
        match self.mode {
            TickMode::Lockstep => {
                let tick = self.clock.tick_of(stamp).ok_or(Rejection::UnknownTick)?;
                if tick < self.tick {
                    return Err(Rejection::Stale);
                }
                if tick > self.tick {
                    return Err(Rejection::UnknownTick);
                }
                if self.line.truncated() {
                    return Err(Rejection::EpisodeOver);
                }
                if already_answered {
                    return Err(Rejection::Duplicate);
                }
            }
            TickMode::Realtime => {
                let nanos = stamp.nanos();
                if nanos > self.stamp().nanos() {
                    return Err(Rejection::UnknownTick);
                }
                if nanos < self.newest_stamp[kind] {
                    return Err(Rejection::Stale);
                }
                self.newest_stamp[kind] = nanos;
            }
        }
        Ok(())
    }

    /// Lock-step: steps once the tick has every command it needs.
    fn complete_tick(&mut self) -> Accepted {
        if self.mode != TickMode::Lockstep {
            return Accepted::Stored;
        }
        let mode_ready = !self.takes_modes() || self.pending_mode.is_some();
        match (self.pending_speed, mode_ready) {
            (Some(speed_index), true) => {
                let mode = self.pending_mode.unwrap_or(SortMode::Basic);
                Accepted::Stepped(self.step(Action::new(speed_index, mode)))
            }
            _ => Accepted::Stored,
        }
    }

    fn step(&mut self, action: Action) -> StepOutcome {
        self.pending_speed = None;
        self.pending_mode = None;
        self.tick += 1;
        self.line.step(action)
    }

    /// Realtime: one timer tick on the held command. At the time limit the next timer tick starts
    /// a new episode instead (the streams carry on), so a live line never stalls. The held command
    /// survives that restart: it was the controller's, not the episode's (an explicit reset does
    /// return to the start speed).
    pub fn timer_tick(&mut self) -> TimerTick {
        if self.line.truncated() {
            let held = self.held;
            let observation = self.reset(None);
            self.held = held;
            TimerTick::Reset(observation)
        } else {
            TimerTick::Stepped(self.step(self.held))
        }
    }
}

/// What a realtime timer tick did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TimerTick {
    Stepped(StepOutcome),
    Reset(Observation),
}

/// One line's entry of a `batch/cmd`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BatchEntry {
    pub stamp: Time,
    pub speed: f64,
    /// None on the basic line (its modes are ignored, or absent).
    pub mode: Option<u8>,
}

impl BatchEntry {
    /// The entry's commands in the order the line takes them: sort mode first, then speed (the
    /// speed completes a lock-step tick either way).
    pub fn commands(&self) -> impl Iterator<Item = Command> {
        self.mode.map(Command::Mode).into_iter().chain([Command::Speed(self.speed)])
    }
}

/// What a node's lines do with the `modes` of a `batch/cmd`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BatchModes {
    /// The advanced line: one mode per line, always.
    Required,
    /// Evolving lines: one mode per line, taken by each line's rules, or none at all (the lines
    /// then get no mode command: enough while their machines have no sort modes).
    Optional,
    /// The basic line: absent, or one per line and ignored.
    Ignored,
}

impl BatchModes {
    /// The rule for the lines a node hosts.
    pub fn of(variant: Variant, evolving: bool) -> Self {
        match (evolving, variant) {
            (true, _) => BatchModes::Optional,
            (false, Variant::Advanced) => BatchModes::Required,
            (false, Variant::Basic) => BatchModes::Ignored,
        }
    }
}

/// The per-line entries of a `batch/cmd` for `lines` lines, or (for a [`Rejection::Malformed`])
/// what is wrong with its shape: every list needs one entry per line, except `modes`, which may
/// be empty unless [`BatchModes::Required`].
pub fn batch_commands(cmd: &LineCommands, lines: usize, modes: BatchModes) -> Result<Vec<BatchEntry>, String> {
    let advanced = match modes {
        BatchModes::Required => true,
        BatchModes::Optional => !cmd.modes.is_empty(),
        BatchModes::Ignored => false,
    };
    let modes_ok = cmd.modes.len() == lines || (modes != BatchModes::Required && cmd.modes.is_empty());
    if cmd.stamp_sec.len() != lines || cmd.stamp_nanosec.len() != lines || cmd.speeds.len() != lines || !modes_ok {
        return Err(format!(
            "batch of {} stamp_sec, {} stamp_nanosec, {} speeds, {} modes for {lines} lines",
            cmd.stamp_sec.len(),
            cmd.stamp_nanosec.len(),
            cmd.speeds.len(),
            cmd.modes.len()
        ));
    }
    Ok((0..lines)
        .map(|k| BatchEntry {
            stamp: Time { sec: cmd.stamp_sec[k], nanosec: cmd.stamp_nanosec[k] },
            speed: cmd.speeds[k],
            mode: advanced.then(|| cmd.modes[k]),
        })
        .collect())
}

/// One line to reset from a `batch/reset`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BatchReset {
    pub line: usize,
    /// None: the line's random streams carry on.
    pub seed: Option<u64>,
}

/// The resets a `batch/reset` asks for on a node of `lines` lines, or why it is refused as a
/// whole: the three lists differ in length, or a line is out of range or named twice.
pub fn batch_resets(request: &ResetLinesRequest, lines: usize) -> Result<Vec<BatchReset>, String> {
    let n = request.lines.len();
    if request.has_seed.len() != n || request.seeds.len() != n {
        return Err(format!(
            "{n} lines, {} has_seed, {} seeds: the three lists must have the same length",
            request.has_seed.len(),
            request.seeds.len()
        ));
    }
    let mut seen = vec![false; lines];
    let mut resets = Vec::with_capacity(n);
    for (i, &k) in request.lines.iter().enumerate() {
        let line = k as usize;
        if line >= lines || seen[line] {
            return Err(format!(
                "line {k} is out of range or repeated: allowed each of 0 ..= {} once",
                lines.saturating_sub(1)
            ));
        }
        seen[line] = true;
        resets.push(BatchReset { line, seed: request.has_seed[i].then_some(request.seeds[i]) });
    }
    Ok(resets)
}

#[cfg(test)]
mod tests;
