"""Build hook: compiles the token path in C (``tokenring/_tokenpath.c``) with setuptools' build_ext.

A wheel gets the compiled module beside the package; an editable install (``pip install -e .``)
gets it in the source tree, where the install imports from. Without a working C compiler the
install still succeeds with a warning: the token path then runs in Python
(``tokenring/node/tokenpath.py``), which ``tokenring bench`` reports.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Any

from hatchling.builders.hooks.plugin.interface import BuildHookInterface

EXTENSION = "tokenring._tokenpath"
SOURCE = "tokenring/_tokenpath.c"


def compile_extension(root: Path, build_dir: Path) -> Path:
    """Compile the extension into ``build_dir``; returns the path of the built module."""
    from setuptools import Distribution, Extension

    extension = Extension(EXTENSION, [str(root / SOURCE)], extra_compile_args=["-O2"])
    distribution = Distribution({"name": "tokenring", "ext_modules": [extension]})
    command = distribution.get_command_obj("build_ext")
    command.build_lib = str(build_dir / "lib")
    command.build_temp = str(build_dir / "temp")
    command.ensure_finalized()
    command.run()
    return Path(command.get_ext_fullpath(EXTENSION))


class TokenPathBuildHook(BuildHookInterface):
    """Adds the compiled token path to the wheel (or the source tree, when editable)."""

    def initialize(self, version: str, build_data: dict[str, Any]) -> None:
        root = Path(self.root)
        if version == "editable":
            for stale in (root / "tokenring").glob("_tokenpath.*.so"):
                stale.unlink()  # a build for another interpreter or an older source
        self._build_dir = Path(tempfile.mkdtemp(prefix="tokenring-build-"))
        try:
            built = compile_extension(root, self._build_dir)
        except Exception as exc:  # no compiler or headers: the Python token path still works
            self.app.display_warning(
                f"tokenring: the C token path was not built ({exc}); the token path runs in Python"
            )
            return
        if version == "editable":
            shutil.copy2(built, root / "tokenring" / built.name)
            return
        build_data["force_include"][str(built)] = f"tokenring/{built.name}"
        build_data["pure_python"] = False
        build_data["infer_tag"] = True

    def finalize(self, version: str, build_data: dict[str, Any], artifact_path: str) -> None:
        shutil.rmtree(getattr(self, "_build_dir", ""), ignore_errors=True)
