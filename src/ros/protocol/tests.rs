//! The unit tests of `ros::protocol`: every rule of lock-step and realtime command handling,
//! batches and resets, pinned without I/O.

use super::*;
use crate::sim::Setup;

fn host(variant: Variant, mode: TickMode) -> HostedLine {
    HostedLine::new(LineConfig::for_setup(Setup::B, variant), 42, SimClock::new(0.5), mode)
}

#[test]
fn lockstep_basic_steps_on_each_speed_for_the_current_tick() {
    let mut h = host(Variant::Basic, TickMode::Lockstep);
    let mut reference = Line::new(LineConfig::for_setup(Setup::B, Variant::Basic), 42);
    for k in 0..50u64 {
        let stamp = h.stamp();
        assert_eq!(stamp, SimClock::new(0.5).stamp(k));
        match h.on_speed(stamp, 0.3).unwrap() {
            Accepted::Stepped(out) => assert_eq!(out, reference.step(Action::new(2, SortMode::Basic))),
            Accepted::Stored => panic!("basic line needs only the speed"),
        }
        assert_eq!(h.on_speed(stamp, 0.3), Err(Rejection::Stale), "the tick was answered");
    }
    assert_eq!(h.on_speed(h.stamp(), 0.3), Err(Rejection::EpisodeOver));
    h.reset(Some(1));
    assert!(matches!(h.on_speed(h.stamp(), 0.3), Ok(Accepted::Stepped(_))));
}

#[test]
fn lockstep_advanced_needs_both_commands_in_any_order() {
    let mut h = host(Variant::Advanced, TickMode::Lockstep);
    let s = h.stamp();
    assert_eq!(h.on_sort_mode(s, 2), Ok(Accepted::Stored));
    assert_eq!(h.on_sort_mode(s, 1), Err(Rejection::Duplicate));
    let Ok(Accepted::Stepped(out)) = h.on_speed(s, 0.4) else { panic!("should step") };
    assert_eq!(out.action, Action::new(3, SortMode::Negative), "the first mode command counts");
    let s = h.stamp();
    assert_eq!(h.on_speed(s, 0.2), Ok(Accepted::Stored));
    assert!(matches!(h.on_sort_mode(s, 0), Ok(Accepted::Stepped(_))));
}

#[test]
fn bad_commands_are_rejected_and_change_nothing() {
    let mut clean = host(Variant::Advanced, TickMode::Lockstep);
    let mut noisy = host(Variant::Advanced, TickMode::Lockstep);
    for k in 0..40 {
        let s = noisy.stamp();
        let future = SimClock::new(0.5).stamp(noisy.tick() + 1);
        assert_eq!(noisy.on_speed(s, f64::NAN), Err(Rejection::InvalidSpeed));
        assert_eq!(noisy.on_speed(s, 0.55), Err(Rejection::InvalidSpeed));
        assert_eq!(noisy.on_speed(s, -3.0), Err(Rejection::InvalidSpeed));
        assert_eq!(noisy.on_sort_mode(s, 7), Err(Rejection::UnknownMode));
        assert_eq!(noisy.on_speed(future, 0.5), Err(Rejection::UnknownTick));
        assert_eq!(noisy.on_speed(Time { sec: 0, nanosec: 1 }, 0.5), Err(Rejection::UnknownTick));
        if k > 0 {
            assert_eq!(noisy.on_speed(SimClock::new(0.5).stamp(0), 0.5), Err(Rejection::Stale));
        }
        let speed = 0.1 * f64::from(k % 10 + 1);
        let mode = (k % 3) as u8;
        for h in [&mut clean, &mut noisy] {
            let s = h.stamp();
            h.on_sort_mode(s, mode).unwrap();
            h.on_speed(s, speed).unwrap();
        }
        assert_eq!(clean.line().last_step(), noisy.line().last_step());
    }
    let mut basic = host(Variant::Basic, TickMode::Lockstep);
    assert_eq!(basic.on_sort_mode(basic.stamp(), 1), Err(Rejection::ModeOnBasicLine));
}

#[test]
fn an_evolving_line_takes_modes_only_while_its_machine_has_them() {
    use crate::sim::evolution::{At, Event};
    let mut upgrade = Event::at(At::Tick(2));
    upgrade.sort_modes = Some(true);
    let mut downgrade = Event::at(At::Episode(1));
    downgrade.sort_modes = Some(false);
    let schedule = Schedule::new(vec![upgrade, downgrade]);
    let config = LineConfig::for_setup(Setup::B, Variant::Basic);
    let mut h =
        HostedLine::with_evolution(config.clone(), 42, schedule.clone(), SimClock::new(0.5), TickMode::Lockstep);
    let mut reference = Line::with_evolution(config, 42, schedule);
    assert!(h.evolving() && !h.takes_modes());
    for _ in 0..2 {
        let s = h.stamp();
        assert_eq!(h.on_sort_mode(s, 1), Err(Rejection::SortModesOff), "no modes before the machine upgrade");
        assert_eq!(h.on_sort_mode(s, 7), Err(Rejection::UnknownMode));
        assert_eq!(h.on_sort_mode(s, 0), Ok(Accepted::Stored), "mode 0 is always valid");
        let Ok(Accepted::Stepped(out)) = h.on_speed(s, 0.3) else { panic!("the speed alone completes the tick") };
        assert_eq!(out, reference.step(Action::new(2, SortMode::Positive)));
    }
    // The upgrade is due at the start of tick 2: its step needs, and takes, a mode.
    assert!(h.takes_modes() && !h.line().sort_modes());
    let s = h.stamp();
    assert_eq!(h.on_speed(s, 0.3), Ok(Accepted::Stored));
    let Ok(Accepted::Stepped(out)) = h.on_sort_mode(s, 2) else { panic!("mode and speed complete the tick") };
    assert_eq!(out, reference.step(Action::new(2, SortMode::Negative)));
    assert_eq!(out.action.mode, SortMode::Negative);
    // Episode 1 takes the modes away again.
    h.reset(Some(3));
    reference.reset(Some(3));
    assert!(!h.takes_modes());
    assert_eq!(h.on_sort_mode(h.stamp(), 2), Err(Rejection::SortModesOff));
    let Ok(Accepted::Stepped(out)) = h.on_speed(h.stamp(), 0.5) else { panic!() };
    assert_eq!(out, reference.step(Action::new(4, SortMode::Basic)));
    // Without a schedule the basic line still refuses every mode as before.
    assert_eq!(
        host(Variant::Basic, TickMode::Lockstep).on_sort_mode(SimClock::new(0.5).stamp(0), 0),
        Err(Rejection::ModeOnBasicLine)
    );
}

#[test]
fn evolving_lines_take_batch_modes_when_given() {
    let t = Time { sec: 1, nanosec: 0 };
    let with = batch_commands(&batch(&[t, t], &[0.3, 0.5], &[1, 2]), 2, BatchModes::Optional).unwrap();
    assert_eq!(with[1].mode, Some(2));
    let without = batch_commands(&batch(&[t, t], &[0.3, 0.5], &[]), 2, BatchModes::Optional).unwrap();
    assert_eq!(without[0].commands().collect::<Vec<_>>(), [Command::Speed(0.3)]);
    assert!(batch_commands(&batch(&[t, t], &[0.3, 0.5], &[1]), 2, BatchModes::Optional).is_err());
    assert_eq!(BatchModes::of(Variant::Basic, true), BatchModes::Optional);
}

#[test]
fn one_client_drives_an_episode_and_a_reset_frees_the_line() {
    let (a, b) = ([1; 12], [2; 12]);
    let mut h = host(Variant::Basic, TickMode::Lockstep);
    assert_eq!(h.speed_from(b, h.stamp(), f64::NAN), Err(Rejection::InvalidSpeed), "a rejected command claims nothing");
    assert!(matches!(h.speed_from(a, h.stamp(), 0.3), Ok(Accepted::Stepped(_))));
    assert_eq!(h.owner(), Some(a));
    let before = h.line().last_step().copied();
    assert_eq!(h.speed_from(b, h.stamp(), 0.9), Err(Rejection::NotOwner));
    assert_eq!(h.line().last_step().copied(), before, "the other client's command changed nothing");
    h.reset(Some(5));
    assert_eq!(h.owner(), None, "a reset, by whoever, frees the line");
    assert!(matches!(h.speed_from(b, h.stamp(), 0.9), Ok(Accepted::Stepped(_))));
    assert_eq!(h.speed_from(a, h.stamp(), 0.3), Err(Rejection::NotOwner));
    // Realtime: the line's own restart ends the episode and its ownership too.
    let mut r = host(Variant::Advanced, TickMode::Realtime);
    assert_eq!(r.sort_mode_from(a, r.stamp(), 1), Ok(Accepted::Stored));
    assert_eq!(r.speed_from(b, r.stamp(), 0.5), Err(Rejection::NotOwner));
    while !matches!(r.timer_tick(), TimerTick::Reset(_)) {}
    assert_eq!(r.speed_from(b, r.stamp(), 0.5), Ok(Accepted::Stored));
}

fn batch(stamps: &[Time], speeds: &[f64], modes: &[u8]) -> LineCommands {
    LineCommands {
        stamp_sec: stamps.iter().map(|t| t.sec).collect(),
        stamp_nanosec: stamps.iter().map(|t| t.nanosec).collect(),
        speeds: speeds.to_vec(),
        modes: modes.to_vec(),
        ..LineCommands::default()
    }
}

#[test]
fn a_batch_command_needs_one_entry_per_line_in_every_list() {
    let t = Time { sec: 1, nanosec: 0 };
    let ok = batch_commands(&batch(&[t, t], &[0.3, 0.5], &[1, 2]), 2, BatchModes::Required).unwrap();
    assert_eq!(ok[1], BatchEntry { stamp: t, speed: 0.5, mode: Some(2) });
    assert_eq!(ok[0].commands().collect::<Vec<_>>(), [Command::Mode(1), Command::Speed(0.3)], "mode first");
    // The basic line ignores modes: absent or one per line.
    for modes in [&[][..], &[7, 7]] {
        let basic = batch_commands(&batch(&[t, t], &[0.3, 0.5], modes), 2, BatchModes::Ignored).unwrap();
        assert_eq!(basic[0].commands().collect::<Vec<_>>(), [Command::Speed(0.3)]);
    }
    let mut wrong_nanos = batch(&[t, t], &[0.3, 0.5], &[1, 2]);
    wrong_nanos.stamp_nanosec.pop();
    for (cmd, variant) in [
        (batch(&[t], &[0.3, 0.5], &[1, 2]), Variant::Advanced),
        (batch(&[t, t], &[0.3], &[1, 2]), Variant::Advanced),
        (batch(&[t, t], &[0.3, 0.5], &[]), Variant::Advanced),
        (batch(&[t, t], &[0.3, 0.5], &[1]), Variant::Basic),
        (batch(&[t, t, t], &[0.3, 0.5, 0.1], &[0, 0, 0]), Variant::Basic),
        (wrong_nanos, Variant::Advanced),
    ] {
        let e = batch_commands(&cmd, 2, BatchModes::of(variant, false)).unwrap_err();
        assert!(e.starts_with("batch of ") && e.ends_with("for 2 lines"), "{e}");
    }
}

#[test]
fn a_batch_reset_names_each_line_once_with_a_seed_flag_and_a_seed() {
    let req = |lines: &[u32], has_seed: &[bool], seeds: &[u64]| ResetLinesRequest {
        lines: lines.to_vec(),
        has_seed: has_seed.to_vec(),
        seeds: seeds.to_vec(),
    };
    let ok = batch_resets(&req(&[2, 0], &[true, false], &[9, 9]), 3).unwrap();
    assert_eq!(ok, [BatchReset { line: 2, seed: Some(9) }, BatchReset { line: 0, seed: None }]);
    assert_eq!(batch_resets(&req(&[], &[], &[]), 3).unwrap(), []);
    let e = batch_resets(&req(&[0, 1], &[true], &[1, 2]), 3).unwrap_err();
    assert!(e.contains("2 lines, 1 has_seed, 2 seeds"), "{e}");
    for lines in [&[3u32][..], &[1, 1], &[u32::MAX]] {
        let n = lines.len();
        let e = batch_resets(&req(lines, &vec![false; n], &vec![0; n]), 3).unwrap_err();
        assert!(e.contains("is out of range or repeated: allowed each of 0 ..= 2 once"), "{e}");
    }
}

#[test]
fn realtime_holds_the_last_valid_command_and_restarts_episodes() {
    let mut h = host(Variant::Advanced, TickMode::Realtime);
    assert_eq!(h.on_speed(h.stamp(), 0.9), Ok(Accepted::Stored));
    assert_eq!(h.on_sort_mode(h.stamp(), 1), Ok(Accepted::Stored));
    let TimerTick::Stepped(first) = h.timer_tick() else { panic!() };
    assert_eq!(first.action, Action::new(8, SortMode::Positive));
    assert_eq!(h.on_speed(h.stamp(), f64::INFINITY), Err(Rejection::InvalidSpeed));
    let ahead = SimClock::new(0.5).stamp(h.tick() + 5);
    assert_eq!(h.on_speed(ahead, 0.1), Err(Rejection::UnknownTick));
    // A lagging stamp is fine in realtime (the line moved on meanwhile); going backwards is not.
    h.timer_tick();
    let before = SimClock::new(0.5).stamp(h.tick() - 1);
    assert_eq!(h.on_speed(before, 0.9), Ok(Accepted::Stored));
    assert_eq!(h.on_speed(h.stamp(), 0.9), Ok(Accepted::Stored));
    assert_eq!(h.on_speed(before, 0.9), Err(Rejection::Stale));
    // A mode for the newer tick does not make the older tick's speed stale (and vice versa).
    let mut g = host(Variant::Advanced, TickMode::Realtime);
    g.timer_tick();
    let (older, newer) = (SimClock::new(0.5).stamp(0), g.stamp());
    assert_eq!(g.on_sort_mode(newer, 1), Ok(Accepted::Stored));
    assert_eq!(g.on_speed(older, 0.9), Ok(Accepted::Stored));
    for _ in 2..50 {
        let TimerTick::Stepped(out) = h.timer_tick() else { panic!("episode still running") };
        assert_eq!(out.action, Action::new(8, SortMode::Positive));
    }
    assert!(matches!(h.timer_tick(), TimerTick::Reset(_)));
    assert_eq!(h.line().episode(), 1);
    let TimerTick::Stepped(out) = h.timer_tick() else { panic!("a new episode runs") };
    assert_eq!(out.action, Action::new(8, SortMode::Positive), "the command survives the automatic restart");
    h.reset(Some(3));
    let TimerTick::Stepped(out) = h.timer_tick() else { panic!() };
    assert_eq!(out.action.speed_index, START_SPEED_INDEX, "an explicit reset returns to the start speed");
}

#[test]
fn a_simulation_reset_restarts_the_line_as_built_and_can_rewind_time() {
    let mut h = host(Variant::Basic, TickMode::Lockstep);
    let first: Vec<_> = (0..50).map(|_| h.on_speed(h.stamp(), 0.3).unwrap()).collect();
    h.reset(None);
    h.on_speed(h.stamp(), 0.3).unwrap();
    let before = h.tick();
    h.restart();
    assert_eq!((h.tick(), h.line().episode(), h.line().step_count()), (before + 1, 0, 0), "time runs on");
    let again: Vec<_> = (0..50).map(|_| h.on_speed(h.stamp(), 0.3).unwrap()).collect();
    assert_eq!(first, again, "the seed's streams from the start");
    h.rewind_time();
    assert_eq!(h.stamp(), Time::default());
    assert_eq!(h.on_speed(SimClock::new(0.5).stamp(1), 0.3), Err(Rejection::UnknownTick), "old stamps name no tick");
}

#[test]
fn a_stopped_line_rejects_commands_and_a_mode_switch_clears_pending_ones() {
    let mut h = host(Variant::Advanced, TickMode::Lockstep);
    h.set_halted(true);
    assert_eq!(h.command_from([1; 12], h.stamp(), Command::Speed(0.3)), Err(Rejection::Stopped));
    h.set_halted(false);
    h.set_mode(TickMode::Realtime);
    assert_eq!(h.command_from([1; 12], h.stamp(), Command::Speed(0.3)), Ok(Accepted::Stored));
    h.set_mode(TickMode::Lockstep);
    assert_eq!(h.mode(), TickMode::Lockstep);
    // The realtime speed does not answer the lock-step tick: a mode alone does not complete it.
    assert_eq!(h.command_from([1; 12], h.stamp(), Command::Mode(1)), Ok(Accepted::Stored));
    assert!(matches!(h.command_from([1; 12], h.stamp(), Command::Speed(0.5)), Ok(Accepted::Stepped(_))));
}

/// The two explanations formatted from the library's speeds and sort modes read as the node has
/// always logged them (the Python bag check's `NODE_REASONS` states the same texts).
#[test]
fn speed_and_mode_rejections_name_the_librarys_speeds_and_modes() {
    assert_eq!(Rejection::InvalidSpeed.explain(), "speed is not one of 0.1, 0.2, ..., 1.0");
    assert_eq!(Rejection::UnknownMode.explain(), "sort mode is not 0 (basic), 1 (positive) or 2 (negative)");
}
