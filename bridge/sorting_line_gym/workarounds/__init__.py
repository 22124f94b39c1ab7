"""Workarounds for defects outside this repository's code, each in a module of its own, so that the
whole can be seen and each can be deleted when its defect is gone. Nothing else in the bridge
implements one: the rest of the bridge calls these modules. The modules import only what their
defect needs (``orphaned_processes`` and ``simultaneous_discovery`` no ROS; the others rclpy,
lazily where they can), and this package imports none of them.

Versions below are those of launch_scripts/requirements-ros.txt: rclpy 7.1 (Jazzy wheels),
rmw_fastrtps 8.4.3, Fast DDS 2.14.5; the node's RustDDS is vendor/rustdds.

``fork_unsafe_dds`` -- rclpy over Fast DDS is not fork-safe.
    Defect: a child forked while rclpy was live inherits the context but not Fast DDS's threads.
    Symptom: the child's first wait blocks forever on a futex in the inherited Fast DDS context
    (Gymnasium's AsyncVectorEnv workers did, when an env had connected in the parent before the
    fork). Measured: seen in those workers; test_vectorizers'
    test_forked_child_with_an_inherited_live_context_gets_a_clear_error checks the error now.
    Seen in: rclpy 7.1 / Fast DDS 2.14. Workaround: fork hooks remember that rclpy was live, and a
    child's first use raises an error naming both pids and the fix (spawn, forkserver, or envs made
    after the fork). Delete when: a child forked from a live context can make a node and step a
    line (drop ``check_not_forked`` and run that test expecting success).

``participant_deletion_hang`` -- deleting a participant can spin for minutes.
    Defect: rmw_fastrtps' participant deletion calls ``DomainParticipant::set_listener(nullptr)``,
    which waits, with an infinite timeout and busy where libstdc++'s condition variable is not on
    steady_clock (the manylinux wheels), for discovery callbacks in flight, while Fast DDS's
    discovery thread waits for the participant's mutex (eProsima/Fast-DDS issue 6513, open, in
    every release). Symptom: ``env.close()`` spinning at 78 % CPU with the GIL held when other
    participants come or go at the same moment; deleting a node's entities hangs the same way.
    Measured: the hangs seen (vectorizers' workers, a Ray EnvRunner) and what did not help are in
    docs/results/reliability.md, "Closing under CPU hogs". Seen in: Fast DDS 2.14.5. Workaround: a
    worker (forked, a multiprocessing worker of any start method, or a process ended by being
    killed: Ray's EnvRunners, ``keep_participant_until_killed``) keeps a never-destroyed node, so
    its participant is never deleted, keeps the nodes its closed envs leave (``retire_node``), and
    ends without DDS teardown (fork and forkserver workers by ``os._exit`` already; a spawn worker's
    final ``sys.exit`` is made an ``os._exit`` with the same code). Other processes delete their
    participant at their last close, before stopping the node they started; the studies' cell pool,
    whose workers run cell after cell, declares ``outlives_its_envs``. benches/close_stress.py
    counts hangs under CPU hogs. Delete when: a Fast DDS wheel that fixes issue 6513 is what rclpy
    uses, and benches/close_stress.py prints 0 hangs under two CPU hogs with every node destroyed.

``simultaneous_discovery`` -- participants that start together lose endpoint announcements.
    Defect: between Fast DDS 2.14 (rclpy) and RustDDS (the node), SEDP announcements exchanged while
    several participants start at once are lost for good. Symptom: a node's reset service never
    becomes ready for its client, even after 60 s. Measured: benches/discovery.py counts which
    clients complete discovery of which nodes; its runs, with and without the lock, and the lock's
    cost at start-up are in docs/results/many-envs.md. Workaround: ``joining_graph``, a host lock
    per network namespace and domain held from a bank's participant start to its handshake. Delete
    when: benches/discovery.py with every participant started at once reports complete discovery,
    and the SubprocVecEnv-16 test passes without it.

``late_matching`` -- the first exchange after discovery can be lost.
    Defect: right after discovery the node may match our request writer before our reply reader,
    or before our state reader; volatile samples sent before matching are dropped. Symptom: the
    first reset's reply, or its step-0 state, never arrives. (The node now waits, at most 2 s, for
    the client's reply reader before it replies, as the rmw layers do: vendor/README.md,
    ros2-client patch 4. A step-0 state has no such guard: a topic's writer cannot know who is
    about to subscribe. So the handshake stays, for the state and for nodes built before.)
    Measured: found by the node tests' harness; short first attempts and what they saved at
    start-up: docs/results/many-envs.md. Seen in: rclpy 7.1 / Fast DDS 2.14 against RustDDS,
    Cyclone DDS 11 against RustDDS.
    Workaround: ``retried_handshake`` repeats the first (seeded, so identical) reset: the bank's on
    a fixed line, the recorder's parameter query and the pytest plugin's first answer of a
    controller (a controller that is still discovering the node misses its first tick the same
    way). A line whose resets count (the evolving line: each is the schedule's next episode) gets
    its first reset once per node, waited for as any reset, and a fresh node when that exchange was
    lost (``ros.bank``); the bag replayer proves the bag's first reset the same way, on a fresh node
    if its messages did not all arrive. Where a timeout alone cannot tell a lost exchange from one
    that happened,
    ``repeated_while_unanswered`` repeats it only while the caller's evidence says nothing
    happened: ``bag.check.closed_loop`` (a reset whose first tick got no answer; a fresh node first when
    the reset had no seed) and the tests' harness (tests/python/support/line_client.py: a reset that
    /diagnostics shows did not happen; bag_golden.py: a golden recording's reset nobody answered).
    Delete when: the first state of a reset is proven to arrive (a reader-side handshake of the
    node's own, or a durable step-0 state), and no test sees a lost first reply or state.

``orphaned_processes`` -- what a process starts is not told when it dies.
    Defect: Linux leaves a dead process's children running, a SIGKILLed Python runs no cleanup,
    and a vectorizer's worker (SB3 2.9 SubprocVecEnv, Gymnasium 1.4 AsyncVectorEnv, with fork)
    waits on a pipe its siblings also hold open, so it never sees its parent die. Symptom: after a
    SubprocVecEnv-16 failure in a full suite, the timed-out script's 15 other workers lived on for
    30 min, each holding a leased line; a SIGKILLed bridge orphaned its node. Measured: the
    orphaned-worker test in test_vectorizers failed on the old code ("outlived its killed parent
    by 30 s") and passes in 2 s, over fork, forkserver and spawn. Workaround: the kernel's
    parent-death signal for workers: ``die_with_multiprocessing_parent`` (an env in a
    multiprocessing worker), ``die_with_parent`` (``studies.cell_pool``'s workers of the benchmark
    and the transfer study, SIGKILL). Delete when: the vectorizers detect a dead parent themselves
    (the orphaned-worker test passes without it). The node processes get the same signal from
    ``line.process.with_parent_death_signal`` (the one ``setpriv --pdeathsig`` launcher, for node
    processes, line servers' nodes, the checked controller and the tests' processes): that one
    stays, the kernel's behaviour being by design.

Kept elsewhere, because they are not Python of the bridge:
- launch_scripts/test.sh runs ``fastdds shm clean`` before and after the tests: processes killed
  by the tests leave Fast DDS shared-memory segments in /dev/shm (229 MB on one machine).
- launch_scripts/fastdds_profile.xml sets 4 MiB socket receive buffers: a client short of CPU lost
  part of a 4-node announcement burst and never matched the endpoints that came by repair (6 of 8
  starts of benches/multihost.py failed under strace, 5 of 5 passed with it); SUBNET mode only.
- vendor/rustdds and vendor/ros2-client carry patches of the node's DDS (vendor/README.md).
Rules that need no code of their own: no ``spin_until_future_complete`` anywhere (it leaks a task
per call in rclpy 7.1; every wait is ``ros.waits.Waiter``'s loop of ``spin_once`` or an rcl wait
set), and bags compare values, never bytes (Fast DDS leaves garbage in CDR padding;
``bag.transport.compare``).
Designs shaped by these defects but not workarounds (they stay when the defects go): line servers
(``line.line_server``: fewer participants per host), the parent-death signal of every process the
bridge starts (``line.process.with_parent_death_signal``), envs that connect at their first reset (a
forked child never inherits a live context), and rclpy initialised without its signal handlers
(``ros.context``: an env is a guest in its user's process).
"""
