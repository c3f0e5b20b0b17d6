"""Every protocol timing constant of the three roles (agent, simworld, monitor), in one place (who is alive:
each role's `Policy` in reconswarm/net/trust/membership.py, built from these).

All of them are wall-clock durations (the processes measure them with `time.monotonic()`), except where
the name says simulated time (`_sim_s`) or a fraction of the realtime period. The defaults are the values
the processes have always used; a test can build a `Timing` with shorter ones.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Timing:
    # ---------------------------------------------------------------------------------------- agent
    # Lockstep: longest wait for a peer's beacon or obstacle set (and for a tick's lost clock or scan); going
    # on without them is a guess (the summary's `deterministic` turns false). Longer than the lease, so that a
    # peer that is gone is dropped by its membership (its token's end) first.
    agent_wait_timeout_s: float = 3.0
    # A peer whose beacons stopped this long ago (alive by its token, but silent) is not waited for (a guess
    # too); longer than the lease for the same reason.
    peer_silent_s: float = 3.0
    # Realtime: a live peer silent this long (wall seconds; at least 3 periods) has left the cells we listen to
    # (or is stuck): its last beacon shows where it was, not where it is, and planned with it is a ghost that can
    # pin an agent in place (seen: a ROS 2 mission where five ghosts held the last agent still for 180 s). Wall
    # time, not ticks: in an overloaded run every beacon is ticks old, yet a live neighbour is still heard.
    realtime_peer_silent_s: float = 1.0
    # Lockstep: the world publishes a tick it waits on again every `republish_s`; nothing from it (a clock, our
    # state) for this long, or its token gone: it stalls (frozen mid-tick, starved), nobody can have a new state
    # to announce, so no wait above is given up, and every wait starts afresh once it speaks again.
    world_quiet_s: float = 1.5
    # Lockstep: while stuck on a tick, announce the beacon (and obstacle set) again this often.
    beacon_again_s: float = 0.5
    # No command for this long (each time the world re-sends the tick we commanded, every `republish_s` while it
    # waits for someone's command, we command it again): the agent opens a new zenoh session (its node, and so
    # its knowledge and peers, are kept). Commands re-sent only: a new session after `resubscribe_world_gone_s`
    # (the world moves on within `step_timeout_s`; a tick it keeps re-sending may be lacking ours).
    resubscribe_s: float = 5.0
    # ... but this long while the world's own token is gone and no clock came since: the world stalled (frozen,
    # starved), and new sessions of every agent at once would only make its return harder (new session ids,
    # subscriptions to propagate). Still a way out if it is our session, not the world, that is broken.
    resubscribe_world_gone_s: float = 15.0
    # Exit 3 if the world sends no clock for this long after the mission began.
    world_silence_s: float = 30.0
    # Realtime: act this fraction of a period after a new state, with whatever has arrived by then.
    realtime_act_fraction: float = 0.25
    # ROS 2 mode: an agent sends no cmd_vel planned from an odometry published more than this many periods (wall
    # time, at the run's speed) before (its attachment's source timestamp against the cmd_vel's); the plant takes a
    # cmd_vel as planned from the oldest tick it published within that long before the cmd_vel was sent (a Twist
    # has no tick: simworld/ros2_io.py), and holds it as the project's own mode holds a command of that tick.
    ros2_plan_age_periods: float = 1.0
    # ROS 2 mode: an agent that sends none for that reason sends a stop (a zero Twist) once its robot's hold is
    # over, then this often while it still sends none: its heartbeat for the world, well inside the world's 2 s
    # of silence after which an agent with a token is not counted alive (`member_fresh_s`); a stop counts as
    # its robot's command in the missed-deadline ratio, so it is sent no more often than that.
    ros2_stop_every_s: float = 0.5
    # While not commanding for more than `waiting_log_s`, log what the next tick lacks, this often.
    waiting_log_s: float = 1.0
    # With nothing queued, the agent looks again after this long.
    agent_poll_s: float = 0.05
    # After the world's end of mission, keep the token this long so the monitor sees the end first.
    agent_end_linger_s: float = 0.5
    # An end clock stands once the world's token has gone (the world closes its session after its end), or
    # after this long with no later clock from the world (whose next clock says someone else claimed the end).
    end_confirm_s: float = 5.0
    # The agent's report (its counters, for the monitor) at least this often: its heartbeat, well inside the
    # monitor's 2 s of silence after which an agent with a token is not counted alive (`member_fresh_s`).
    telemetry_s: float = 0.5

    # -------------------------------------------------------------------------------------- simworld
    # Wait this long for every agent's and the monitor's liveliness token (the readiness barrier).
    start_timeout_s: float = 60.0
    # Lockstep: longest wait for a live agent's command at one tick.
    step_timeout_s: float = 5.0
    # Lockstep: re-publish a tick that has waited this long for commands.
    republish_s: float = 0.5
    # A missing command is held this long (simulated time), then the robot stops.
    hold_sim_s: float = 0.2
    # With no agent reachable, hold the world this long before ending the mission.
    no_agents_grace_s: float = 30.0
    # Lockstep: step timeouts in a row after which an agent is not waited for until it commands again.
    strikes: int = 2
    # Simworld itself not run for this long (SIGSTOP, a starved machine): its waits start afresh.
    self_stall_s: float = 1.0
    # After the last clock, keep the session this long so the last messages reach the monitor.
    world_end_linger_s: float = 0.3
    # The truth's publisher keeps this many ticks for the monitor to recover (a truth published while the
    # world's session was coming back from a stall of its own went nowhere: seen as a one-tick gap under load),
    # and announces its newest sequence number this often when it changed (so a lost last tick is found too).
    truth_cache_ticks: int = 32
    truth_heartbeat_s: float = 0.25

    # --------------------------------------------------------------------------------------- monitor
    # After the world's last clock, how long to wait for the last states.
    end_grace_s: float = 3.0
    # The monitor wakes for each tick's truth, and at least this often without one (end of mission, commits).
    monitor_wake_s: float = 0.05
    # Agents lost (or back) within this much wall time of each other count as one network event.
    burst_s: float = 1.0
    # Commit the record at least every this much simulated time ...
    commit_sim_s: float = 0.5
    # ... and every this much wall time (also how often the rejection counters are refreshed).
    commit_wall_s: float = 0.5
    # The world's clock silent this long (or its token gone) is a world stall (one world_stalled event).
    world_stall_s: float = 2.0

    # --------------------------------------------------------------------------- simworld and monitor
    # Who is alive (membership.Membership: a token AND own data, commands for the world, reports for the monitor):
    # an agent whose data has been silent this long of wall time AND this long of simulated time is not alive
    # (neither a stalled world, during which nobody sends, nor a fast realtime clock makes a live agent look dead).
    member_fresh_s: float = 2.0
    member_fresh_sim_s: float = 2.0
    # ... and one not heard since its token appeared (or since the start, or since our own link came back).
    member_grace_s: float = 10.0
    member_grace_sim_s: float = 5.0
    # Lockstep: the world stops counting a token whose agent has sent nothing since a tick it waits on began this
    # much after an agent's own wait for its peers (`agent_wait_timeout_s`) would have given up.
    await_margin_s: float = 1.0
    # An agent's token that goes counts as gone this much later (unless back by then): a dying router takes
    # every token with it a moment before our own session sees its link go (uplink.py).
    token_confirm_s: float = 0.3
    # Our own session connected to a router again: tokens that went have this long to come back (each client
    # retries its router at most every 4 s, zenoh's default) and everyone's data gets the start's grace.
    relink_settle_s: float = 10.0

    # --------------------------------------------------------------------------------------- session
    # Admission (admission.Pins): another session may speak for an agent once the one pinned to it has been silent
    # this long (a restarted agent's new session takes over).
    repin_after_s: float = 1.0
    # A frozen process is declared gone after this (zenoh's default 10 s is too slow for robots).
    lease_ms: int = 2000
    # Opening a session retries until the router answers or this passes (100+ processes starting at once on
    # a loaded machine took more than 20 s; the world's start barrier, 120 s by default, is the real bound).
    session_open_timeout_s: float = 60.0


TIMING = Timing()  # the defaults every process runs with
