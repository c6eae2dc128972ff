"""The simulated runtime: threaded code one task at a time on a virtual clock that jumps when every
task waits; the same seed gives the same interleaving, another seed another one."""

from __future__ import annotations

import queue
import threading
import time

import pytest

from tokenring.runtime import RealRuntime, current, using
from tokenring.runtime.sim import TASK_KINDS, Deadlock, SimRuntime


def ping_pong(sim: SimRuntime, rounds: int = 50) -> list[tuple[float, str]]:
    """Two tasks sleeping different periods and trading a queue's items; the trace of who did
    what when."""
    trace: list[tuple[float, str]] = []
    box = sim.queue()
    done = sim.event()

    def producer() -> None:
        for k in range(rounds):
            sim.sleep(0.013)
            box.put(k)
            trace.append((sim.monotonic(), f"put {k}"))

    def consumer() -> None:
        for _ in range(rounds):
            item = box.get()
            trace.append((sim.monotonic(), f"got {item}"))
            sim.sleep(0.007)
        done.set()

    def main() -> None:
        sim.spawn(producer, "producer")
        sim.spawn(consumer, "consumer")
        assert done.wait(10.0)

    sim.run(main)
    return trace


def test_virtual_time_jumps_when_every_task_waits() -> None:
    sim = SimRuntime(seed=1)
    started = time.monotonic()
    trace = ping_pong(sim, rounds=200)
    assert time.monotonic() - started < 5.0  # 2.6 simulated seconds, not waited for
    assert trace[-1][0] == pytest.approx(200 * 0.013, abs=0.02)
    assert [t for t, _ in trace] == sorted(t for t, _ in trace)


def test_the_same_seed_gives_the_same_trace() -> None:
    assert ping_pong(SimRuntime(seed=7)) == ping_pong(SimRuntime(seed=7))


def test_seeds_explore_interleavings_of_tasks_ready_at_once() -> None:
    def order(seed: int) -> tuple[str, ...]:
        sim = SimRuntime(seed=seed)
        seen: list[str] = []

        def main() -> None:
            gate = sim.event()
            for name in "abcd":
                sim.spawn(lambda name=name: (gate.wait(), seen.append(name)), name)
            sim.sleep(1.0)
            gate.set()
            sim.sleep(1.0)

        sim.run(main)
        return tuple(seen)

    assert order(3) == order(3)
    assert len({order(s) for s in range(30)}) > 1
    assert SimRuntime(seed=5, jitter=False).jitter is False


def test_timeouts_return_false_at_the_virtual_deadline() -> None:
    sim = SimRuntime()
    seen = []

    def main() -> None:
        event = sim.event()
        seen.append((event.wait(2.5), sim.monotonic()))
        q = sim.queue()
        with pytest.raises(queue.Empty):
            q.get(timeout=0.5)
        seen.append(sim.monotonic())
        cond = sim.condition()
        with cond:
            seen.append(cond.wait_for(lambda: False, timeout=1.0))
        seen.append(sim.monotonic())

    sim.run(main)
    assert seen == [(False, 2.5), 3.0, False, 4.0]


def test_a_lock_held_across_a_wait_makes_the_other_task_wait() -> None:
    sim = SimRuntime(seed=2)
    trace = []

    def holder(lock) -> None:
        with lock:
            trace.append(("holder in", sim.monotonic()))
            sim.sleep(1.0)
            trace.append(("holder out", sim.monotonic()))

    def main() -> None:
        lock = sim.lock()
        t = sim.spawn(lambda: holder(lock), "holder")
        sim.sleep(0.1)
        with lock:
            trace.append(("main in", sim.monotonic()))
        t.join()

    sim.run(main)
    assert trace == [("holder in", 0.0), ("holder out", 1.0), ("main in", 1.0)]


def test_a_bounded_queue_blocks_its_producer() -> None:
    sim = SimRuntime()
    put_at = []

    def main() -> None:
        q = sim.queue(maxsize=1)

        def consumer() -> None:
            for _ in range(3):
                sim.sleep(1.0)
                q.get()

        sim.spawn(consumer, "consumer")
        for k in range(3):
            q.put(k)
            put_at.append(sim.monotonic())
        with pytest.raises(queue.Full):
            q.put_nowait(9)

    sim.run(main)
    assert put_at == [0.0, 1.0, 2.0]


def test_every_task_waiting_for_ever_is_a_deadlock_not_a_hang() -> None:
    sim = SimRuntime()

    def main() -> None:
        never = sim.event()
        sim.spawn(lambda: sim.event().wait(), "stuck")
        never.wait()

    with pytest.raises(Deadlock, match="every simulated task waits"):
        sim.run(main)
    sim.close()


def test_a_failing_task_fails_the_run() -> None:
    sim = SimRuntime()

    def boom() -> None:
        raise ValueError("nope")

    def main() -> None:
        sim.spawn(boom, "boom")
        sim.sleep(1.0)

    with pytest.raises(RuntimeError, match="simulated task 'boom' failed"):
        sim.run(main)


def test_a_thread_outside_the_simulation_is_refused() -> None:
    import threading

    sim = SimRuntime()
    errors: list[str] = []

    def main() -> None:
        def stray() -> None:
            try:
                sim.sleep(1.0)
            except RuntimeError as exc:
                errors.append(str(exc))

        t = threading.Thread(target=stray)
        t.start()
        t.join()

    sim.run(main)
    assert errors and "not the running simulated task" in errors[0]


def test_the_real_runtime_is_the_default_and_using_swaps_it() -> None:
    assert isinstance(current(), RealRuntime)
    sim = SimRuntime()
    with using(sim):
        assert current() is sim
    assert isinstance(current(), RealRuntime)


def test_a_million_simulated_seconds_of_timers_take_no_real_time() -> None:
    sim = SimRuntime(seed=4)
    ticks = []

    def ticker(period: float, name: str) -> None:
        while sim.monotonic() < 1e6:
            sim.sleep(period)
        ticks.append(name)

    def main() -> None:
        for period in (997.0, 1009.0, 1013.0):
            sim.spawn(lambda period=period: ticker(period, str(period)), f"t{period}")
        sim.sleep(1.1e6)

    started = time.monotonic()
    sim.run(main)
    assert sorted(ticks) == ["1009.0", "1013.0", "997.0"]
    assert time.monotonic() - started < 10.0


def test_an_rlock_is_reentrant_for_its_owner_and_a_condition_over_it_releases_it_whole() -> None:
    sim = SimRuntime(seed=3)
    trace = []

    def main() -> None:
        lock = sim.rlock()
        cond = sim.condition(lock)

        def other() -> None:
            with lock:  # free while main waits on the condition, held twice as it was
                trace.append(("other in", sim.monotonic()))
                cond.notify()

        with lock, lock:
            sim.spawn(other, "other")
            sim.sleep(1.0)  # other waits for the lock meanwhile
            assert cond.wait(5.0)
            trace.append(("main back", sim.monotonic()))
        with pytest.raises(RuntimeError):
            lock.release()

    sim.run(main)
    assert trace == [("other in", 1.0), ("main back", 1.0)]


def test_a_timer_fires_at_its_virtual_time_unless_cancelled() -> None:
    sim = SimRuntime()
    fired = []

    def main() -> None:
        kept = sim.timer(2.0, lambda what: fired.append((what, sim.monotonic())), ("kept",))
        dropped = sim.timer(1.0, lambda: fired.append(("dropped", sim.monotonic())))
        kept.start()
        dropped.start()
        sim.sleep(0.5)
        dropped.cancel()
        sim.sleep(3.0)
        assert not kept.is_alive()

    sim.run(main)
    assert fired == [("kept", 2.0)]


def test_a_simple_queue_current_thread_and_rng_have_the_real_runtimes_shape() -> None:
    real = RealRuntime()
    assert real.monotonic is time.monotonic and real.current_thread() is threading.current_thread()
    assert type(real.simple_queue()) is queue.SimpleQueue
    sim = SimRuntime(seed=9)
    seen = []

    def main() -> None:
        box = sim.simple_queue()
        handle = sim.spawn(lambda: seen.append(sim.current_thread().name) or box.put("x"), "worker")
        seen.append(box.get(timeout=1.0))
        handle.join()
        seen.append(sim.current_thread().name)
        seen.append(sim.rng().random())

    sim.run(main)
    again = SimRuntime(seed=9)
    assert seen[:3] == ["worker", "x", "main"]
    assert seen[3] == again.rng().random() != SimRuntime(seed=10).rng().random()


@pytest.mark.parametrize("tasks", TASK_KINDS)
def test_closing_ends_every_parked_task_and_leaves_no_thread(tasks: str) -> None:
    sim = SimRuntime(seed=1, tasks=tasks)
    unwound = []

    def parked(name: str) -> None:
        lock = sim.lock()
        try:
            with lock:
                sim.event().wait()
        finally:
            unwound.append(name)
            sim.sleep(1.0)  # a wait while unwinding ends the task at once
            unwound.append("never")

    def main() -> None:
        for name in "abc":
            sim.spawn(lambda name=name: parked(name), name)
        sim.sleep(0.001)  # every ready task runs before a timer: a, b and c park
        sim.spawn(lambda: None, "never started")  # still ready when main returns

    before = set(threading.enumerate())
    with sim:
        sim.run(main)
        # a thread per task still parked (main's own is not one); greenlets are no threads
        assert len(set(threading.enumerate()) - before) == (4 if tasks == "threads" else 0)
    assert sorted(unwound) == ["a", "b", "c"]
    assert not set(threading.enumerate()) - before
    assert sim.close() == []


def test_greenlets_and_threads_make_the_same_choices() -> None:
    traces = {kind: ping_pong(SimRuntime(seed=11, tasks=kind)) for kind in TASK_KINDS}
    assert traces["greenlet"] == traces["threads"]
    for kind in TASK_KINDS:
        sim = SimRuntime(tasks=kind)
        with pytest.raises(Deadlock):
            sim.run(lambda sim=sim: sim.event().wait())
        assert sim.close() == []


def test_a_wait_only_its_own_timer_can_end_moves_the_clock_without_a_switch() -> None:
    sim = SimRuntime(seed=1)

    def main() -> None:
        sim.sleep(1.0)  # nothing else runs before: the clock moves on, the baton stays
        assert sim.event().wait(0.5) is False
        assert sim.monotonic() == 1.5
        assert sim.switches == 0
        sim.spawn(lambda: sim.sleep(0.1), "other")
        sim.sleep(1.0)  # the other task is ready: it runs first
        assert sim.monotonic() == 2.5

    sim.run(main)
    assert sim.switches > 0


def test_tasks_started_by_tasks_do_not_run_out_of_recursion_depth() -> None:
    # a greenlet starts on top of the stack that first switches to it: started from deep inside
    # another task's wait, each generation used to start deeper (255 nodes' tasks overflowed)
    sim = SimRuntime(seed=1)
    ran = []

    def link(k: int) -> None:
        ran.append(k)
        if k < 1000:
            task = sim.spawn(lambda: link(k + 1), f"t{k}")
            sim.sleep(0.001)
            task.join()

    sim.run(lambda: link(0))
    assert ran == list(range(1001)) and sim.close() == []
