"""``tokenring console``: the Darmstadt program's operator's screen and keys (seed 000 §6.6, §8).

:mod:`.state` gathers what is shown from the live feed and main's PC link; :mod:`.screen` draws it
in the terminal (``--ui ncurses``); :mod:`.plain` is the ``stdout`` and ``none`` interfaces;
:mod:`.keys` carries out the keys of table 8.2 (:mod:`modules.pc.operator`) in order.
"""
