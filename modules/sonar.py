"""The sonar module's user program (placeholder until its real program lands)."""

from modules.common.placeholder import PlaceholderProgram


class Program(PlaceholderProgram):
    module = "sonar"
