"""The project's exception family.

Every error raised on purpose by :mod:`switchobs_core` is a :class:`SwitchobsError`.
Each concrete type also derives from the builtin it refines, so a caller may catch
either the precise type or the builtin (the python-control convention).
"""

from __future__ import annotations

__all__ = [
    "one_line",
    "SwitchobsError",
    "InvalidArgument",
    "InvalidSystem",
    "UnobservableSystem",
    "NoiseModelError",
    "DesignError",
    "InfeasibleDesign",
    "VerificationError",
    "KalmanDesignError",
    "UndetectableSchedule",
    "RiccatiError",
    "PrecisionError",
    "CovarianceError",
    "GainTableError",
    "ScheduleError",
]


class SwitchobsError(Exception):
    """Base class of every error raised on purpose by switchobs."""


class InvalidArgument(SwitchobsError, ValueError):
    """An argument has the wrong shape, a non-finite entry or an impossible value."""


class InvalidSystem(InvalidArgument):
    """A system description (matrices, channels, YAML file) is malformed."""


class UnobservableSystem(InvalidSystem):
    """Assumption A1 fails: (A, [C_1; ...; C_N]) is not observable."""


class NoiseModelError(InvalidArgument):
    """A noise model (measurement std, process intensity, P0) is malformed."""


class DesignError(SwitchobsError, RuntimeError):
    """The offline gain design could not be carried out."""


class InfeasibleDesign(DesignError):
    """No decay rate / gain satisfies the requested design conditions."""


class VerificationError(DesignError):
    """A synthesized gain failed its a-posteriori floating-point verification."""


class KalmanDesignError(DesignError):
    """The offline Kalman design could not be carried out (sample pattern, convergence)."""


class UndetectableSchedule(KalmanDesignError):
    """The sampled periodic pair is not detectable: some unstable mode is never seen."""


class RiccatiError(DesignError):
    """The periodic Riccati recursion did not converge, or a covariance became invalid."""


class PrecisionError(DesignError):
    """The design needs more dynamic range than double precision carries (a channel unseen for so
    long that its error grows past what 16 digits resolve): refused at design time, naming the
    numbers and what would fix it (:mod:`switchobs_core.design.precision`)."""


class CovarianceError(RiccatiError):
    """The online Riccati recursion lost positive definiteness (or finiteness) of its covariance:
    the arithmetic ran out of digits at run time.

    Raised inside a family's step (:mod:`switchobs_core.runtime.families.online`), which restarts
    its recursion from the noise model's ``P0``, corrects with that gain and returns the message
    as its correction's ``lost``: the observer keeps answering and withdraws its covariance with
    that reason (``SwitchedObserver.covariance_withdrawn``). ``correction``: optional, for a
    caller that raises it with the correction already made.
    """

    def __init__(self, message: str, correction: object = None) -> None:
        super().__init__(message)
        self.correction = correction


class GainTableError(SwitchobsError, ValueError):
    """A gain table file is unreadable, corrupt, of another version or for another system."""


class ScheduleError(InvalidArgument):
    """A switching cycle or schedule is malformed (tau <= 0, s outside (0, 1), ...)."""


def one_line(err: BaseException, *, with_type: bool = False) -> str:
    """``err`` as one line for a command's error message: whitespace folded, the exception's
    type name when it has no text (or, with ``with_type``, always in front of it)."""
    text = " ".join(str(err).split())
    if not text:
        return type(err).__name__
    return f"{type(err).__name__}: {text}" if with_type else text
