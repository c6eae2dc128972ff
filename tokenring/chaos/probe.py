"""The command workload ``tokenring chaos`` runs on every node (a user program file).

Each node sends numbered commands (``VECTOR``, accepted by every inbox) in bursts: a run of
1 to 300 commands to one other node, then a run to another, chosen at random — so sequence
numbers wrap and interleave between targets as the robot's own traffic does — and takes every
command from its own inbox, now and then busy for a while after a take (its inbox locked, as a
robot's program is). A command carries its sender's run tag (random per program incarnation)
and its number, so (sender, run, n) names it across crashes and respawns.

With ``$TOKENRING_PROBE_LEDGER`` set to a directory, every incarnation appends a JSON-lines
ledger there, ``ledger-<node>-<pid>-<run>.jsonl``, flushed line by line so that it survives a crash:

- ``{"ev": "start", "node", "run", "pid", "t"}``
- ``{"ev": "send", "to", "run", "n", "t"}``, then ``{"ev": "outcome", "to", "n", "result", "t"}``
  with result ``acked``, ``unacked`` (transmitted, not acknowledged) or ``untransmitted``
- ``{"ev": "take", "from", "run", "n", "t"}``
- ``{"ev": "quiesced", "t"}`` once a file ``quiesce`` appears in the directory: it sends no more
  and every send has its outcome; ``{"ev": "stop", "t"}`` when it ends cleanly.

The judge compares the ledgers after the ring stopped: lost = acknowledged but taken by no
incarnation of the target; duplicated = taken twice. Without the variable the program keeps
the same facts in memory for ``report()`` (the last 4000 of each).

Its clock, threads and random draws are the runtime's (:mod:`tokenring.runtime`), so that the
same program runs in a simulation (``tokenring sim --chaos``), where a node's crash is
:meth:`Program.crash`: the ledger ends there, as a killed process's does.
"""

import json
import os
import random

from tokenring import runtime
from tokenring.node.program import UserProgram

HALF = 1 << 15  # a VECTOR argument is an i16: a 30-bit value travels as two 15-bit halves
#: after a take, the receiver is busy this often, for a time drawn from BUSY_S: its inbox stays
#: locked meanwhile, so commands arrive at a locked inbox (refused, offered again) as they do on
#: a robot whose programs take time; in virtual time a program's work takes none without it
BUSY_P = 1 / 16
BUSY_S = (0.005, 0.05)


def split(value):
    return value >> 15, value & (HALF - 1)


def join(high, low):
    return (high << 15) | low


class Program(UserProgram):
    def setup(self):
        self.os.set_own_input_id()
        self.others = [n for n in self.os.protocol.nodes if n != self.os.name]
        self._rt = runtime.current()
        self.run_tag = self._rt.rng().randrange(1, 1 << 30)
        self.random = random.Random(self.run_tag)
        self.pace = random.Random(self.run_tag ^ 0x5EED)  # the receiver's own draws
        self.target = None
        self.burst = 0
        self.number = 0
        self.acked = []
        self.taken = {}
        self.duplicates = 0
        self.quiesced = False
        self._lock = self._rt.lock()
        self._file = None
        self._dir = os.environ.get("TOKENRING_PROBE_LEDGER")
        if self._dir:
            name = f"ledger-{self.os.node_id}-{os.getpid()}-{self.run_tag}.jsonl"
            path = os.path.join(self._dir, name)
            self._file = open(path, "a", buffering=1)  # noqa: SIM115 - open for the program's life
        self._log(ev="start", node=self.os.node_id, run=self.run_tag, pid=os.getpid())

    def _log(self, **entry):
        if self._file is None:
            return
        entry["t"] = self._rt.time()
        line = json.dumps(entry, separators=(",", ":")) + "\n"
        with self._lock:
            if not self._file.closed:
                self._file.write(line)  # line-buffered: one write(2) a line, kept if we are killed

    def _quiesce_requested(self):
        return self._dir is not None and os.path.exists(os.path.join(self._dir, "quiesce"))

    def run(self):
        self._rt.spawn(self._receive, "probe-receive")
        while self.running:
            if not self.others or self.quiesced:
                self.sleep(0.05)
                continue
            if self.burst <= 0:
                self.target = self.random.choice(self.others)
                self.burst = self.random.randint(1, 300)
            self.burst -= 1
            target_id = self.os.protocol.nodes[self.target].id
            if self._quiesce_requested():
                self.quiesced = True
                self._log(ev="quiesced")
                continue
            self.number += 1
            n = self.number
            run_hi, run_lo = split(self.run_tag)
            n_hi, n_lo = split(n)
            self._log(ev="send", to=target_id, run=self.run_tag, n=n)
            box = self.os.send_command(self.target, "VECTOR", x1=run_hi, y1=run_lo, x2=n_hi, y2=n_lo)
            while not box.done.wait(0.5):
                if not self.running:
                    box.cancel()
                    break
            if not box.done.is_set():
                result = "untransmitted"  # stopping: the fate of a command still in the token is unknown
            elif box.acknowledged:
                result = "acked"
                self.acked.append((target_id, n))
            else:
                result = "unacked" if box.transmitted else "untransmitted"
            self._log(ev="outcome", to=target_id, n=n, result=result)
            self.sleep(0.01)

    def _receive(self):
        while self.running:
            cmd = self.os.receive_command(timeout=0.1)
            if cmd is None or cmd.name != "VECTOR":
                continue
            a = cmd.args
            run, n = join(a["x1"], a["y1"]), join(a["x2"], a["y2"])
            self._log(ev="take", **{"from": cmd.sender}, run=run, n=n)
            key = f"{cmd.sender}:{run}"
            seen = self.taken.setdefault(key, set())
            if n in seen:
                self.duplicates += 1
            seen.add(n)
            if self.pace.random() < BUSY_P:
                self.sleep(self.pace.uniform(*BUSY_S))

    def crash(self):
        """The process is killed (a simulated crash): nothing more reaches the ledger."""
        with self._lock:
            if self._file is not None:
                self._file.close()

    def teardown(self):
        self._log(ev="stop")
        if self._file is not None:
            with self._lock:
                self._file.close()

    def report(self):
        return {
            "run": self.run_tag,
            "quiesced": self.quiesced,
            "acked": self.acked[-4000:],  # [target ID, n]
            "taken": {k: sorted(v)[-4000:] for k, v in self.taken.items()},  # "sender:run" -> [n]
            "duplicates": self.duplicates,
        }
