"""The command workload ``tokenring chaos`` runs on every node (a user program file).

Each node sends numbered commands (``VECTOR_COUNTER``, accepted by every inbox) to the next
node of protocol.yaml in a loop and records which numbers were acknowledged; it records every
number it takes from its own inbox. Lost: acknowledged but never taken; duplicated: taken twice.
"""

from tokenring.program import UserProgram


class Program(UserProgram):
    def setup(self):
        self.os.set_own_input_id()
        names = list(self.os.protocol.nodes)
        mine = self.os.name
        self.target = names[(names.index(mine) + 1) % len(names)] if mine in names else None
        self.acked = []
        self.taken = {}
        self.duplicates = 0
        self.sequence = 0

    def run(self):
        import threading

        threading.Thread(target=self._receive, name="probe-receive", daemon=True).start()
        while self.running:
            if self.target is None:
                self.sleep(0.1)
                continue
            self.sequence = (self.sequence + 1) & 0xFFFF
            box = self.os.send_command(self.target, "VECTOR_COUNTER", count=self.sequence)
            if box.done.wait(1.0) and box.acknowledged:
                self.acked.append(self.sequence)
            self.sleep(0.01)

    def _receive(self):
        while self.running:
            cmd = self.os.receive_command(timeout=0.1)
            if cmd is None or cmd.name != "VECTOR_COUNTER":
                continue
            seen = self.taken.setdefault(str(cmd.sender), [])
            if cmd.args["count"] in seen[-64:]:
                self.duplicates += 1
            seen.append(cmd.args["count"])

    def report(self):
        return {
            "target": self.target,
            "acked": self.acked[-4000:],
            "taken": {k: v[-4000:] for k, v in self.taken.items()},
            "duplicates": self.duplicates,
        }
