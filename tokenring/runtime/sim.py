"""The simulated runtime: the same threaded code, one task at a time, on a virtual clock.

Every task is a greenlet (a stack of its own in the calling thread, switched to directly), or with
``tasks="threads"`` a real thread parked on a private lock; either way only the task holding the
*baton* runs. A task gives the baton up only inside this runtime's primitives (sleep, an
event's, lock's, condition's or queue's wait): the scheduler then hands it to a ready task, chosen
with the seeded random generator, or — when every task waits — moves the virtual clock on to the
earliest timer and wakes what it frees (trio's autojump clock, Go's ``testing/synctest``). The same
seed gives the same interleaving and the same clock readings, run after run; another seed explores
another interleaving. Code between two primitives runs as one step, as it would between two
preemptions that happen not to come.

Rules for code that runs here: every wait goes through the runtime (a ``time.sleep`` or a plain
``threading.Event`` would stall the whole simulation on the real clock), and no task holds a plain
lock across a runtime wait. A wait that can never end — every task waiting, no timer left — is a
:class:`Deadlock`, raised in the task that called :meth:`SimRuntime.run`. :meth:`SimRuntime.close`
ends the tasks still parked, one at a time, so that no task (and no thread) outlives the
simulation. Both kinds of task make the same choices: a seed gives the same run with either.

Greenlets are the default (a hand-over is a stack switch in one thread, where two OS threads
passing a lock cost two context switches and the interpreter lock's hand-off); the threads are
kept for where greenlet is missing, and ``TOKENRING_SIM_TASKS=threads`` asks for them.
"""

from __future__ import annotations

import contextlib
import heapq
import itertools
import os
import queue as _queue
import random
import threading
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

from tokenring.errors import TokenRingError

try:
    from greenlet import GreenletExit, getcurrent, greenlet
except ImportError:  # pragma: no cover - a platform without its wheel: the tasks are threads
    greenlet = None
    _NO_GREENLET = object()

    def getcurrent() -> Any:
        """No greenlet is ever current (a task's ``glet`` is None): _me() checks the thread."""
        return _NO_GREENLET


#: the kinds of task a :class:`SimRuntime` can run its tasks as
TASK_KINDS = ("greenlet", "threads")

if greenlet is not None:
    from greenlet import error as _greenlet_error

    _Collected: type[BaseException] = GreenletExit
else:  # pragma: no cover

    class _greenlet_error(Exception):  # type: ignore[no-redef]
        """Never raised: there are no greenlets."""

    class _Collected(BaseException):  # type: ignore[no-redef]
        """Never raised: there are no greenlets."""


#: the simulated wall clock's start (``time()``): fixed, so stamps and logs repeat run after run
EPOCH_S = 991_353_600.0


class Deadlock(TokenRingError):
    """Every simulated task waits and no timer will wake any of them."""


class _Shutdown(BaseException):
    """Raised inside a parked task when the simulation is closed: its thread unwinds and ends."""


class _Task:
    """One simulated thread: what carries it (a greenlet, or a thread and its gate) and its wait."""

    def __init__(self, index: int, name: str) -> None:
        self.index = index
        self.name = name
        # threads: a raw lock, held while the task may not run, released once to hand it the
        # baton (a C call where a Semaphore's is Python under a Condition)
        self.gate: Any = None
        self.glet: Any = None  # greenlets: the task's own
        self.waiting_on: _WaitList | None = None
        self.wait_id = 0  # which wait a timer belongs to (a stale timer wakes nobody)
        self.timed_out = False
        self.done = False
        self.finished: SimEvent | None = None
        self.error: BaseException | None = None
        self.ident: int | None = None
        self.handle: SimThread | None = None
        self.thread: threading.Thread | None = None  # the OS thread that carries it


class _WaitList:
    """The tasks waiting on one object, first come first woken."""

    def __init__(self) -> None:
        self.tasks: deque[_Task] = deque()


class SimRuntime:
    """A deterministic scheduler and virtual clock (see the module docstring).

    ``seed`` chooses among ready tasks; ``jitter`` False always takes the one ready longest (a
    single canonical interleaving)."""

    name = "sim"
    simulated = True

    def __init__(self, seed: int = 0, *, jitter: bool = True, tasks: str | None = None) -> None:
        if tasks is None:
            tasks = os.environ.get("TOKENRING_SIM_TASKS") or (
                "greenlet" if greenlet is not None else "threads"
            )
        if tasks not in TASK_KINDS:
            raise ValueError(f"tasks must be one of {', '.join(TASK_KINDS)}, not {tasks!r}")
        if tasks == "greenlet" and greenlet is None:
            raise RuntimeError("tasks='greenlet' needs the greenlet package")
        self.seed = seed
        self.jitter = jitter
        #: what carries each task: "greenlet" (one thread, stacks switched) or "threads"
        self.tasks = tasks
        self._greenlets = tasks == "greenlet"
        self.schedule_rng = random.Random(seed)  # which ready task runs next
        self.now = 0.0
        self.switches = 0
        self._ready: list[_Task] = []
        self._timers: list[tuple[float, int, _Task, int]] = []
        self._order = itertools.count()
        self._tasks: dict[int, _Task] = {}  # by thread ident
        self._all: list[_Task] = []
        self._main: _Task | None = None
        self._starter: Any = None  # greenlets: where every task's greenlet starts (_start_tasks)
        self._current: _Task | None = None
        self._deadlocked = False
        self._closing = False
        self.failures: list[tuple[str, BaseException]] = []
        # what the code under test draws at random (incarnations, fault dice), kept apart from
        # the scheduler's choices so that one does not shift the other
        self._entropy = random.Random(f"tokenring-sim-entropy:{seed}")

    def __enter__(self) -> SimRuntime:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the clock -------------------------------------------------------------------------------
    def monotonic(self) -> float:
        return self.now

    def time(self) -> float:
        return EPOCH_S + self.now

    def sleep(self, seconds: float) -> None:
        task = self._current
        if task is None or task.glet is not getcurrent():  # _me()'s check, inlined for greenlets
            task = self._me()
        if seconds <= 0:
            self._ready.append(task)  # a yield: the others ready now go first, in the seed's order
            self._park(task)
            return
        if not self._ready and not self._closing:  # _wait()'s fast path, inlined for the wire time
            deadline = self.now + seconds
            timers = self._timers
            while timers:
                _, _, other, wait_id = timers[0]
                if other.wait_id == wait_id and not other.done:
                    break
                heapq.heappop(timers)
            if not timers or timers[0][0] > deadline:
                self.now = deadline
                return
        self._wait(task, None, seconds)

    # -- primitives --------------------------------------------------------------------------------
    def event(self) -> SimEvent:
        return SimEvent(self)

    def lock(self) -> SimLock:
        return SimLock(self)

    def rlock(self) -> SimRLock:
        return SimRLock(self)

    def condition(self, lock: Any = None) -> SimCondition:
        return SimCondition(self, lock)

    def queue(self, maxsize: int = 0) -> SimQueue:
        return SimQueue(self, maxsize)

    def simple_queue(self) -> SimQueue:
        return SimQueue(self)

    def timer(self, interval: float, function: Callable[..., Any], args: Iterable[Any] = ()) -> SimTimer:
        """:class:`threading.Timer` on the virtual clock, not started yet."""
        return SimTimer(self, interval, function, tuple(args))

    def rng(self) -> random.Random:
        """A random generator drawn from the seed: the same run after run."""
        return random.Random(self._entropy.getrandbits(64))

    def current_thread(self) -> SimThread:
        """The running task's handle (what :func:`threading.current_thread` is to threads)."""
        handle = self._me().handle
        assert handle is not None
        return handle

    def spawn(self, target: Callable[[], Any], name: str, daemon: bool = True) -> SimThread:
        """A new task, ready to run when the scheduler picks it (the caller goes on first)."""
        if self._closing:
            raise RuntimeError("the simulation is closed")
        task = _Task(len(self._all), name)
        task.finished = SimEvent(self)
        self._all.append(task)
        handle = task.handle = SimThread(self, task)
        if self._greenlets:
            # its parent is where its body returns to: the task the baton goes to then (_exit)
            main = self._main
            task.glet = greenlet(lambda *_: self._body(task, target), main.glet if main is not None else None)
        else:
            task.gate = threading.Lock()
            task.gate.acquire()

            def carry() -> None:
                task.ident = threading.get_ident()
                self._tasks[task.ident] = task
                task.gate.acquire()
                self._body(task, target)

            thread = task.thread = threading.Thread(target=carry, name=f"sim-{name}", daemon=True)
            thread.start()
        self._ready.append(task)
        return handle

    def _body(self, task: _Task, target: Callable[[], Any]) -> _Task | None:
        """A task's life: ``target``, its failure recorded, then the baton handed on for good
        (greenlets: the task to start next, if it is one never run, for _start_tasks)."""
        try:
            if self._closing:
                return None
            target()
        except _Shutdown:
            return None
        except _Collected:  # its greenlet was collected parked (a runtime never closed)
            self._closing = True
            return None
        except BaseException as exc:  # a task's failure is the run's, reported by run()
            task.error = exc
            self.failures.append((task.name, exc))
        finally:
            task.done = True
        assert task.finished is not None
        task.finished.set()
        return self._exit(task)

    # -- running -------------------------------------------------------------------------------------
    def run(self, main: Callable[[], Any]) -> Any:
        """Run ``main`` as the first task on this thread; the others run while it waits. Returns
        what ``main`` returns; a task's exception is raised here once ``main`` is done."""
        if self._main is not None:
            raise RuntimeError("a simulated runtime runs once")
        task = _Task(len(self._all), "main")
        task.ident = threading.get_ident()
        task.finished = SimEvent(self)
        task.handle = SimThread(self, task)
        if self._greenlets:
            task.glet = getcurrent()
            for other in self._all:  # spawned before run(): their bodies return here too
                if not other.glet:
                    other.glet.parent = task.glet
            self._starter = greenlet(self._start_tasks)
            self._starter.switch()  # it starts here, as shallow as run() itself, and comes back
        else:
            task.gate = threading.Lock()
            task.gate.acquire()
        self._all.append(task)
        self._tasks[task.ident] = task
        self._main = self._current = task
        try:
            result = main()
        finally:
            task.done = True
        if self.failures:
            name, exc = self.failures[0]
            raise RuntimeError(f"simulated task {name!r} failed: {exc!r}") from exc
        return result

    def _start_tasks(self) -> None:
        """Greenlets: start every task's greenlet from here, at one shallow depth. A greenlet
        starts on top of whichever stack switches into it first, and inherits that stack's
        Python recursion depth: tasks started by tasks started by tasks (a ring of 255 nodes)
        would otherwise run out of recursion depth. Whoever switches here passes the task."""
        task = getcurrent().parent.switch()  # back to run(); resumed with the first to start
        while True:
            task = task.glet.switch()  # returns when something hands the next one over

    def close(self, timeout: float = 5.0) -> list[str]:
        """End every parked task, one at a time: each unwinds from the wait it is parked in
        (its ``finally`` blocks run, a further wait ends it at once) and its greenlet or thread
        ends. The runtime takes no more work. Returns the names of tasks that did not end (a
        thread blocked outside the runtime for ``timeout`` real seconds; a greenlet of another
        thread than the caller's); safe to call twice."""
        self._closing = True
        stuck = []
        for task in self._all:
            if task is self._main or task.done:
                continue
            if self._greenlets:
                glet = task.glet
                if glet is None or glet.dead:
                    continue
                if not glet:  # never started: nothing to unwind
                    task.done = True
                    continue
                self._current = task
                try:
                    glet.parent = getcurrent()  # back here once it has unwound
                    glet.switch()
                except (ValueError, _greenlet_error):  # another thread's greenlet
                    pass
                if not glet.dead:
                    stuck.append(task.name)
                continue
            if task.thread is None:
                continue
            self._current = task
            task.gate.release()
            task.thread.join(timeout)
            if task.thread.is_alive():
                stuck.append(task.name)
        self._current = None
        starter, self._starter = self._starter, None
        if starter is not None and starter:
            with contextlib.suppress(ValueError, _greenlet_error):
                starter.parent = getcurrent()
                starter.throw()  # GreenletExit: it ends
        return stuck

    def until(self, seconds: float) -> None:
        """Let the simulation run ``seconds`` of virtual time from now (the caller sleeps)."""
        self.sleep(seconds)

    # -- the scheduler -------------------------------------------------------------------------------
    def _me(self) -> _Task:
        """The running task, checked: the caller must be it (or one unwinding in close())."""
        task = self._current
        if self._greenlets:
            mine = getcurrent()
            if task is not None and task.glet is mine:
                return task
            task = next((t for t in self._all if t.glet is mine), None)
            if task is not None and self._closing:
                return task
        else:
            task = self._tasks.get(threading.get_ident())
            if task is not None and (task is self._current or self._closing):
                return task
        raise RuntimeError(
            f"{threading.current_thread().name} is not the running simulated task "
            "(a thread started without the runtime, or a wait outside it)"
        )

    def _wait(self, task: _Task, waits: _WaitList | None, timeout: float | None) -> bool:
        """Park ``task`` on ``waits`` (None: a plain sleep) until woken or ``timeout`` passes;
        True if woken, False on the timeout."""
        if self._closing and task is not self._main:
            raise _Shutdown
        if timeout is not None:
            deadline = self.now + timeout if timeout > 0.0 else self.now
            if not self._ready:
                # nothing is ready: the earliest live timer runs next, and if that is this wait's
                # own, handing the baton round would come straight back - the clock moves on here
                timers = self._timers
                while timers:
                    _, _, other, wait_id = timers[0]
                    if other.wait_id == wait_id and not other.done:
                        break
                    heapq.heappop(timers)  # stale: _pick would drop it first as well
                if not timers or timers[0][0] > deadline:
                    self.now = deadline
                    return False
        task.wait_id += 1
        task.timed_out = False
        task.waiting_on = waits
        if waits is not None:
            waits.tasks.append(task)
        if timeout is not None:
            heapq.heappush(self._timers, (deadline, next(self._order), task, task.wait_id))
        self._park(task)
        return not task.timed_out

    def _wake(self, waits: _WaitList, count: int | None = None) -> None:
        """Make up to ``count`` (None: all) waiters of ``waits`` ready, first come first."""
        tasks = waits.tasks
        ready = self._ready
        for _ in range(len(tasks) if count is None else min(count, len(tasks))):
            task = tasks.popleft()
            task.waiting_on = None
            task.wait_id += 1  # its timer is stale now
            ready.append(task)

    def _pick(self) -> _Task | None:
        """The next task to run: a ready one (by the seed), else the earliest timer's."""
        if self._ready:
            index = (
                self.schedule_rng.randrange(len(self._ready)) if self.jitter and len(self._ready) > 1 else 0
            )
            return self._ready.pop(index)
        while self._timers:
            deadline, _, task, wait_id = heapq.heappop(self._timers)
            if task.wait_id != wait_id or task.done:
                continue  # woken before its timeout
            self.now = max(self.now, deadline)
            if task.waiting_on is not None:
                task.waiting_on.tasks.remove(task)
                task.waiting_on = None
            task.timed_out = True
            task.wait_id += 1
            return task
        return None

    def _park(self, task: _Task) -> None:
        """Hand the baton on and wait for it back."""
        if self._closing and task is not self._main:
            raise _Shutdown  # unwinding: nothing runs any more
        ready = self._ready
        if ready:  # _next() inlined for the common case
            nxt = ready.pop(self.schedule_rng.randrange(len(ready)) if self.jitter and len(ready) > 1 else 0)
            self.switches += 1
            self._current = nxt
        else:
            nxt = self._next()
        if nxt is not task:
            if self._greenlets:
                try:
                    if nxt.glet:  # running: switch to where it parked
                        nxt.glet.switch()
                    else:  # never run: started from _start_tasks
                        self._starter.switch(nxt)
                except _Collected:
                    self._closing = True  # collected while parked: no wait may switch again
                    raise
            else:
                nxt.gate.release()
                task.gate.acquire()
        if self._closing and task is not self._main:
            raise _Shutdown
        if self._deadlocked and task is self._main:
            self._deadlocked = False
            raise Deadlock(
                f"every simulated task waits and no timer is left at t={self.now:.6f} s: "
                + ", ".join(t.name for t in self._all if not t.done and t.waiting_on is not None)
            )

    def _next(self) -> _Task:
        """Who gets the baton now (the task that called run() if nothing will ever run again:
        it hears of the deadlock); it counts as a switch even when it is the caller again."""
        nxt = self._pick()
        if nxt is None:
            self._deadlocked = True
            nxt = self._main
            assert nxt is not None
            if nxt.waiting_on is not None:
                nxt.waiting_on.tasks.remove(nxt)
                nxt.waiting_on = None
            nxt.wait_id += 1
        self.switches += 1
        self._current = nxt
        return nxt

    def _exit(self, task: _Task) -> _Task | None:
        """A finished task hands the baton on for good (greenlets: its body returns into the
        next task, or into _start_tasks with the next task when that one never ran yet)."""
        if self._closing:
            return None
        nxt = self._next()
        if not self._greenlets:
            nxt.gate.release()
            return None
        if nxt.glet:
            task.glet.parent = nxt.glet
            return None
        task.glet.parent = self._starter
        return nxt


class SimThread:
    """A simulated task's handle, as much of :class:`threading.Thread` as the ring uses."""

    def __init__(self, sim: SimRuntime, task: _Task) -> None:
        self._sim = sim
        self._task = task
        self.name = task.name
        self.daemon = True

    def is_alive(self) -> bool:
        return not self._task.done

    def join(self, timeout: float | None = None) -> None:
        assert self._task.finished is not None
        self._task.finished.wait(timeout)


class SimEvent:
    """:class:`threading.Event` on the virtual clock."""

    def __init__(self, sim: SimRuntime) -> None:
        self._sim = sim
        self._flag = False
        self._waits = _WaitList()

    def is_set(self) -> bool:
        return self._flag

    def set(self) -> None:
        self._flag = True
        if self._waits.tasks:
            self._sim._wake(self._waits)

    def clear(self) -> None:
        self._flag = False

    def wait(self, timeout: float | None = None) -> bool:
        if self._flag:
            return True
        sim = self._sim
        sim._wait(sim._me(), self._waits, timeout)
        return self._flag


class SimLock:
    """:class:`threading.Lock`: contended only when its holder waits inside it."""

    def __init__(self, sim: SimRuntime) -> None:
        self._sim = sim
        self._held = False
        self._waits = _WaitList()

    def acquire(self, blocking: bool = True, timeout: float = -1) -> bool:
        if not self._held:
            self._held = True
            return True
        if not blocking:
            return False
        sim = self._sim
        deadline = None if timeout < 0 else sim.now + timeout
        while self._held:
            left = None if deadline is None else deadline - sim.now
            if left is not None and left <= 0:
                return False
            sim._wait(sim._me(), self._waits, left)
        self._held = True
        return True

    def release(self) -> None:
        if not self._held:
            raise RuntimeError("release unlocked lock")
        self._held = False
        if self._waits.tasks:
            self._sim._wake(self._waits, 1)

    def locked(self) -> bool:
        return self._held

    __enter__ = acquire

    def __exit__(self, *exc: object) -> None:
        if not self._held:
            raise RuntimeError("release unlocked lock")
        self._held = False
        if self._waits.tasks:
            self._sim._wake(self._waits, 1)


class SimRLock:
    """:class:`threading.RLock`: its owner may take it again; others wait until it is free."""

    def __init__(self, sim: SimRuntime) -> None:
        self._sim = sim
        self._owner: _Task | None = None
        self._count = 0
        self._waits = _WaitList()

    def acquire(self, blocking: bool = True, timeout: float = -1) -> bool:
        sim = self._sim
        me = sim._current
        if me is None or me.glet is not getcurrent():  # _me()'s check, inlined for greenlets
            me = sim._me()
        owner = self._owner
        if owner is None:
            self._owner, self._count = me, 1
            return True
        if owner is me:
            self._count += 1
            return True
        if owner is not None:
            if not blocking:
                return False
            deadline = None if timeout < 0 else sim.now + timeout
            while self._owner is not None:
                left = None if deadline is None else deadline - sim.now
                if left is not None and left <= 0:
                    return False
                sim._wait(me, self._waits, left)
        self._owner, self._count = me, 1
        return True

    def release(self) -> None:
        if self._owner is None or self._owner is not self._sim._me():
            raise RuntimeError("cannot release un-acquired lock")
        self._count -= 1
        if not self._count:
            self._owner = None
            if self._waits.tasks:
                self._sim._wake(self._waits, 1)

    __enter__ = acquire

    def __exit__(self, *exc: object) -> None:
        # release() (the owner is whoever runs: the with block's own task)
        if self._owner is None:
            raise RuntimeError("cannot release un-acquired lock")
        self._count -= 1
        if not self._count:
            self._owner = None
            if self._waits.tasks:
                self._sim._wake(self._waits, 1)

    def _release_save(self) -> int:
        """Release however deep it is held (a condition's wait); the depth, to restore."""
        count, self._count, self._owner = self._count, 0, None
        self._sim._wake(self._waits, 1)
        return count

    def _acquire_restore(self, count: int) -> None:
        self.acquire()
        self._count = count


class SimCondition:
    """:class:`threading.Condition` over a :class:`SimLock` (its own unless given one)."""

    def __init__(self, sim: SimRuntime, lock: Any = None) -> None:
        self._sim = sim
        self._lock = lock if lock is not None else SimLock(sim)
        self._waits = _WaitList()

    def __enter__(self) -> bool:
        return bool(self._lock.acquire())

    def __exit__(self, *exc: object) -> None:
        self._lock.release()

    def acquire(self, *args: Any) -> bool:
        return bool(self._lock.acquire(*args))

    def release(self) -> None:
        self._lock.release()

    def wait(self, timeout: float | None = None) -> bool:
        sim = self._sim
        lock = self._lock
        if isinstance(lock, SimRLock):  # released however deep it is held, restored after
            saved = lock._release_save()
            try:
                return sim._wait(sim._me(), self._waits, timeout)
            finally:
                lock._acquire_restore(saved)
        lock.release()
        try:
            return sim._wait(sim._me(), self._waits, timeout)
        finally:
            lock.acquire()

    def wait_for(self, predicate: Callable[[], Any], timeout: float | None = None) -> Any:
        sim = self._sim
        deadline = None if timeout is None else sim.now + timeout
        result = predicate()
        while not result:
            left = None if deadline is None else deadline - sim.now
            if left is not None and left <= 0:
                break
            self.wait(left)
            result = predicate()
        return result

    def notify(self, n: int = 1) -> None:
        self._sim._wake(self._waits, n)

    def notify_all(self) -> None:
        self._sim._wake(self._waits)


class SimQueue:
    """:class:`queue.Queue` on the virtual clock (raises the standard ``queue.Empty``/``Full``)."""

    def __init__(self, sim: SimRuntime, maxsize: int = 0) -> None:
        self._sim = sim
        self.maxsize = maxsize
        self._items: deque[Any] = deque()
        self._getters = _WaitList()
        self._putters = _WaitList()

    def qsize(self) -> int:
        return len(self._items)

    def empty(self) -> bool:
        return not self._items

    def full(self) -> bool:
        return 0 < self.maxsize <= len(self._items)

    def put(self, item: Any, block: bool = True, timeout: float | None = None) -> None:
        if not 0 < self.maxsize <= len(self._items):
            self._items.append(item)
            getters = self._getters.tasks
            if getters:  # _wake(self._getters, 1), inlined: a consumer is handed every item
                task = getters.popleft()
                task.waiting_on = None
                task.wait_id += 1
                self._sim._ready.append(task)
            return
        sim = self._sim
        deadline = None if timeout is None else sim.now + timeout
        while self.full():
            left = None if deadline is None else deadline - sim.now
            if not block or (left is not None and left <= 0):
                raise _queue.Full
            sim._wait(sim._me(), self._putters, left)
        self._items.append(item)
        if self._getters.tasks:
            sim._wake(self._getters, 1)

    def put_nowait(self, item: Any) -> None:
        self.put(item, block=False)

    def get(self, block: bool = True, timeout: float | None = None) -> Any:
        if self._items:
            item = self._items.popleft()
            if self._putters.tasks:
                self._sim._wake(self._putters, 1)
            return item
        sim = self._sim
        if block and timeout is None:  # a consumer's loop: wait until an item comes
            me = sim._current
            if me is None or me.glet is not getcurrent():
                me = sim._me()
            while not self._items:
                sim._wait(me, self._getters, None)
        else:
            deadline = None if timeout is None else sim.now + timeout
            while not self._items:
                left = None if deadline is None else deadline - sim.now
                if not block or (left is not None and left <= 0):
                    raise _queue.Empty
                sim._wait(sim._me(), self._getters, left)
        item = self._items.popleft()
        if self._putters.tasks:
            sim._wake(self._putters, 1)
        return item

    def get_nowait(self) -> Any:
        return self.get(block=False)


class SimTimer:
    """:class:`threading.Timer` on the virtual clock: ``function(*args)`` after ``interval``
    simulated seconds in a task of its own, unless cancelled first."""

    def __init__(
        self, sim: SimRuntime, interval: float, function: Callable[..., Any], args: tuple[Any, ...]
    ) -> None:
        self._sim = sim
        self.interval = interval
        self.function = function
        self.args = args
        self.daemon = True
        self.finished = SimEvent(sim)
        self._handle: SimThread | None = None

    def start(self) -> None:
        def fire() -> None:
            if not self.finished.wait(self.interval):
                self.function(*self.args)
            self.finished.set()

        self._handle = self._sim.spawn(fire, "timer")

    def cancel(self) -> None:
        self.finished.set()

    def is_alive(self) -> bool:
        return self._handle is not None and self._handle.is_alive()

    def join(self, timeout: float | None = None) -> None:
        if self._handle is not None:
            self._handle.join(timeout)
