"""The suite's sections, in the order they run and appear in bench/RESULTS.md."""

SECTIONS = (
    "scaling",
    "transports",
    "runtime",
    "load",
    "commands",
    "profile",
    "recovery",
    "download",
    "spurious",
)
#: run only when named in ``--sections`` (RESULTS.md takes them from their latest run otherwise)
SLOW_SECTIONS = ("spurious",)
QUICK_SECTIONS = ("scaling", "transports", "commands", "profile")
