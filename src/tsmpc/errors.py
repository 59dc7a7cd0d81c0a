"""The package's exception hierarchy.

Every error raised on purpose by tsmpc derives from :class:`TsmpcError` and also from the
built-in exception a caller would naturally catch (``ValueError`` for bad input, ...).
"""

from __future__ import annotations

__all__ = [
    "CertificateError",
    "ClusterError",
    "ConfigError",
    "DataFormatError",
    "DesignError",
    "NonFiniteError",
    "SolverError",
    "TsmpcError",
]


class TsmpcError(Exception):
    """Root of every error tsmpc raises on purpose."""


class ConfigError(TsmpcError, ValueError):
    """A configuration value is missing, unknown, of the wrong type or out of range."""


class NonFiniteError(TsmpcError, ValueError):
    """A state, input or measurement contains NaN or inf."""


class DataFormatError(TsmpcError, ValueError):
    """A reference, track or data file does not have the expected format."""


class SolverError(TsmpcError, RuntimeError):
    """An optimisation solver failed where no fallback exists (offline designs)."""


class CertificateError(TsmpcError, RuntimeError):
    """An LMI design was returned by the solver but its certificate does not hold."""


class DesignError(TsmpcError, ValueError):
    """No certified LMI design exists for a configuration (its boxes, weights, vehicle or rates):
    an input problem — the message names the LMI, where it fails and the settings that would
    help."""


class ClusterError(TsmpcError, RuntimeError):
    """The Dask cluster of a sweep could not be started (the machine, not the input: exit 1)."""
