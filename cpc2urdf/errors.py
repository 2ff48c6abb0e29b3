"""One exception family for everything cpc2urdf rejects.

Every error a user can cause (a bad file, a bad argument, degenerate data) derives from
:class:`Cpc2UrdfError`. The CLI prints its message as one line and exits with code 2; the
Python API lets it propagate. Messages name the file, the field or joint, and what was expected.
"""

from __future__ import annotations

import difflib

# names an UnknownNameError lists in full; with more, the half most like the one asked for
UNKNOWN_NAME_LISTED = 24


class Cpc2UrdfError(Exception):
    """Base class of every error cpc2urdf raises on purpose."""


class InputFileError(Cpc2UrdfError):
    """A file is missing, unreadable, not JSON, or has the wrong format tag.

    Args:
        path: The file (or ``"<string>"``).
        problem: What is wrong, naming the field where there is one.
    """

    def __init__(self, path: object, problem: str) -> None:
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


class SpecError(Cpc2UrdfError):
    """A robot spec or model describes an impossible robot (unknown parent, bad limits, NaN)."""


class UnknownNameError(Cpc2UrdfError):
    """A joint or frame name that the robot does not have.

    Args:
        kind: ``"joint"`` or ``"frame"``.
        name: The name that was asked for.
        known: The names that exist.
    """

    def __init__(self, kind: str, name: str, known: list[str] | tuple[str, ...]) -> None:
        self.kind = kind
        self.name = name
        self.known = list(known)
        if len(self.known) <= UNKNOWN_NAME_LISTED:
            listed = f"known {kind}s: {', '.join(self.known)}"
        else:  # a whole robot (TIAGo: ~180 frames): the most alike, not a 3 kB line
            close = difflib.get_close_matches(
                str(name), [str(k) for k in self.known], n=UNKNOWN_NAME_LISTED // 2, cutoff=0.5
            )
            if close:
                listed = f"closest known {kind}s: {', '.join(close)} (of {len(self.known)})"
            else:
                listed = f"known {kind}s: {', '.join(self.known[:UNKNOWN_NAME_LISTED])}, ... ({len(self.known)} in all)"
        super().__init__(f"unknown {kind} {name!r}; {listed}")


class OutputError(Cpc2UrdfError):
    """An output file cannot be written (missing folder, no permission)."""


class DegenerateDataError(Cpc2UrdfError):
    """The data cannot determine what was asked (a joint never moved, too few poses, ...)."""


class ConfigurationError(Cpc2UrdfError):
    """A joint configuration of the wrong shape, non-finite, or outside the joint limits."""


class InconsistentDataError(DegenerateDataError):
    """The data disagree with the model beyond chance: a fit far from the data's own noise
    statement (above or below it), an implausible robot size, gross outliers.

    Args:
        message: One line naming the most likely cause and what to change.
        report: The evidence (a consistency report), or None.
    """

    def __init__(self, message: str, report: object = None) -> None:
        super().__init__(message)
        self.report = report


__all__ = [
    "ConfigurationError",
    "Cpc2UrdfError",
    "DegenerateDataError",
    "InconsistentDataError",
    "InputFileError",
    "OutputError",
    "SpecError",
    "UnknownNameError",
]
