"""Returns the ball: every n from ping goes back as n + 1."""

from tokenring.program import UserProgram


class Program(UserProgram):
    def setup(self):
        self.os.set_own_input_id()
        self.score = self.os.publish()

    def run(self):
        returned = 0
        while self.running:
            ball = self.os.receive_command(timeout=0.2)
            if ball is None or ball.name != "BALL":
                continue
            while self.running and not self.os.deliver("ping", "BALL", n=ball.args["n"] + 1, timeout=2.0):
                pass
            returned += 1
            self.score.write(returned=returned)
