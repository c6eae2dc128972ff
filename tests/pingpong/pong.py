"""Returns the ball: every n from ping goes back as n + 1."""

from tokenring import UserProgram


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
            # one deliver resends the same command until acknowledged, so ping takes it once; a
            # new deliver after a timeout would be a second command ping could take too. Not
            # delivered at all, ping serves its ball again (and notes it)
            if not self.os.deliver("ping", "BALL", n=ball.args["n"] + 1, timeout=30.0):
                continue
            returned += 1
            self.score.write(returned=returned)
