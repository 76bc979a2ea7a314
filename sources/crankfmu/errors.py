"""The one base of crankfmu's user-facing errors.

Every error a user can cause with what they pass in (a scene file, an SSP archive, a `--set`
value, a command-line option) or that ends a run early derives from `CrankfmuError`, and its
message says what is wrong and where (file, key, what is allowed; or time, component and
variable). `crankfmu.cli.main` maps it to exit status 2 with `error: <message>`, and an
interrupted run (`RunInterrupted`, Ctrl-C) to 130: no traceback for anything a user can do.
"""
from __future__ import annotations

from .runtime.model import CrankfmuError  # noqa: F401 - defined with the physics (bottom layer)

# Limits on what a scene may ask for; each is named in the error that enforces it.
MAX_STEPS = 10_000_000          # communication steps of one run ([master].max_steps raises it)
MAX_SCENE_FILE_BYTES = 4 << 20  # a scene file (TOML) read into memory
MAX_NAME_LENGTH = 100           # a scene name becomes a file name: results/<name>.csv
MAX_TIME = 1e12                 # |start_time|, |stop_time| [s]: beyond this a step is lost in
                                # the time's rounding
MAX_STUDY_RUNS = 10_000         # runs of one study (a sweep's grid, an accuracy sweep's
                                # settings): each is a scene copy and a task in memory
MAX_RECORD_BYTES = 1 << 30      # a run's recorded values in memory (rows x columns x 8 bytes);
                                # its CSV is about 2.5 times that


class InterruptedRun(CrankfmuError):
    """Base of a run stopped by the user (Ctrl-C): exit status 130."""

    exit_status = 130


class SceneError(CrankfmuError, ValueError):
    """A scene file problem; the message names the file and the key."""

    def __init__(self, path, key: str, message: str):
        self.path, self.key = path, key
        super().__init__(f"{path}: {key}: {message}")


class OptionError(CrankfmuError, ValueError):
    """A command-line option, an API argument or a master option outside what it allows."""


def warning_text(message, category) -> str:
    """A Python warning as crankfmu shows it (after "warning: "), on one line and without the
    file and source line it came from: `<Category>: <message>`, the message alone for a
    UserWarning."""
    kind = "" if category is UserWarning else f"{category.__name__}: "
    return kind + " ".join(str(message).split())
