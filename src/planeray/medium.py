"""The optical parameters of a homogeneous scattering medium, as one frozen value.

:class:`Medium` is what every subsurface-scattering model of planeray takes
(:func:`planeray.mc.mc_line_profile`, the dipole of :mod:`planeray.mc.diffusion`,
:func:`planeray.kernels.line_kernel`, the ``wax`` scene, the Mitsuba reference),
so the coefficients travel together, by name, validated once.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from .errors import InputError

__all__ = ["Medium", "as_medium"]

_FIELDS = ("sigma_s", "sigma_a", "g", "n", "thickness_mm")


@dataclass(frozen=True)
class Medium:
    """A homogeneous medium with Henyey-Greenstein scattering.

    Parameters
    ----------
    sigma_s : float
        Scattering coefficient, mm^-1 (``>= 0``).
    sigma_a : float
        Absorption coefficient, mm^-1 (``>= 0``; ``sigma_s + sigma_a > 0``).
    g : float
        Henyey-Greenstein anisotropy, ``-1 < g < 1`` (0 isotropic, > 0 forward).
    n : float
        Relative refractive index of the medium against the outside (1 = index
        matched), the same on both faces.
    thickness_mm : float
        Slab thickness in mm; ``math.inf`` (default) for a semi-infinite medium.

    Every value is stored as a Python ``float``.  Construction validates them
    and raises :class:`planeray.errors.InputError` (a ``ValueError``) naming the
    offending field.  Instances are immutable and hashable; derive a changed
    copy with :meth:`replace`.

    Attributes
    ----------
    sigma_s_prime : float
        Reduced scattering coefficient ``sigma_s (1 - g)``, mm^-1.
    sigma_t : float
        Extinction coefficient ``sigma_s + sigma_a``, mm^-1.
    albedo : float
        Single-scattering albedo ``sigma_s / sigma_t``.
    transport_mfp_mm : float
        Transport mean free path ``1 / (sigma_a + sigma_s')``, mm.

    See Also
    --------
    Medium.from_reduced : build from ``sigma_s'`` by the similarity relation.

    Examples
    --------
    >>> from planeray.medium import Medium
    >>> m = Medium(sigma_s=1.0, sigma_a=0.01, g=0.9)
    >>> round(m.sigma_s_prime, 12)
    0.1
    >>> m.n, m.thickness_mm
    (1.0, inf)
    >>> round(m.transport_mfp_mm, 6)
    9.090909
    >>> wax = Medium.from_reduced(0.3, 0.003, g=0.8, n=1.4)
    >>> wax.sigma_s
    1.5000000000000002
    >>> wax.replace(g=0.0).sigma_s_prime
    1.5000000000000002
    >>> Medium.from_dict(wax.to_dict()) == wax
    True
    >>> Medium(sigma_s=1.0, sigma_a=0.0, g=1.0)
    Traceback (most recent call last):
    ...
    planeray.errors.InputError: g must lie in (-1, 1), got 1.0
    """

    sigma_s: float
    sigma_a: float
    g: float
    n: float = 1.0
    thickness_mm: float = math.inf

    def __post_init__(self):
        values = {}
        for name in _FIELDS:
            raw = getattr(self, name)
            if isinstance(raw, (bool, str, bytes)):
                raise InputError(f"{name} must be a number, got {raw!r}")
            try:
                value = float(raw)
            except (TypeError, ValueError):
                raise InputError(f"{name} must be a number, got {raw!r}") from None
            values[name] = value
            object.__setattr__(self, name, value)
        for name in ("sigma_s", "sigma_a", "g", "n"):
            if not math.isfinite(values[name]):
                raise InputError(f"{name} must be finite, got {values[name]}")
        sigma_s, sigma_a, g, n, thickness = (values[k] for k in _FIELDS)
        if sigma_s < 0:
            raise InputError(f"sigma_s must be >= 0, got {sigma_s}")
        if sigma_a < 0:
            raise InputError(f"sigma_a must be >= 0, got {sigma_a}")
        if not sigma_s + sigma_a > 0:
            raise InputError(
                f"need sigma_s + sigma_a > 0 (a medium that interacts), got sigma_s {sigma_s}, sigma_a {sigma_a}"
            )
        if not -1.0 < g < 1.0:
            raise InputError(f"g must lie in (-1, 1), got {g}")
        if not n > 0:
            raise InputError(f"n must be positive, got {n}")
        if not thickness > 0:  # also rejects NaN; inf is the semi-infinite medium
            raise InputError(f"thickness_mm must be positive (inf: semi-infinite), got {thickness}")

    # ------------------------------------------------------------ derived values
    @property
    def sigma_s_prime(self) -> float:
        """Reduced scattering coefficient ``sigma_s (1 - g)``, mm^-1."""
        return self.sigma_s * (1.0 - self.g)

    @property
    def sigma_t(self) -> float:
        """Extinction coefficient ``sigma_s + sigma_a``, mm^-1."""
        return self.sigma_s + self.sigma_a

    @property
    def albedo(self) -> float:
        """Single-scattering albedo ``sigma_s / sigma_t``."""
        return self.sigma_s / self.sigma_t

    @property
    def transport_mfp_mm(self) -> float:
        """Transport mean free path ``1 / (sigma_a + sigma_s')``, mm."""
        return 1.0 / (self.sigma_a + self.sigma_s_prime)

    @property
    def semi_infinite(self) -> bool:
        """Whether the medium is a half-space (``thickness_mm`` is infinite)."""
        return math.isinf(self.thickness_mm)

    # ------------------------------------------------------------ constructors
    @classmethod
    def from_reduced(cls, sigma_s_prime, sigma_a, g, n=1.0, thickness_mm=math.inf) -> Medium:
        """The medium with reduced scattering ``sigma_s_prime`` at anisotropy ``g``.

        Similarity relation: ``sigma_s = sigma_s_prime / (1 - g)``, so media of the
        same ``sigma_s'`` share their diffusion regime whatever ``g``.

        Examples
        --------
        >>> Medium.from_reduced(0.5, 0.01, g=0.0).sigma_s
        0.5
        """
        try:
            sigma_s_prime, g = float(sigma_s_prime), float(g)
        except (TypeError, ValueError):
            raise InputError(f"sigma_s_prime and g must be numbers, got {sigma_s_prime!r}, {g!r}") from None
        if not -1.0 < g < 1.0:
            raise InputError(f"g must lie in (-1, 1), got {g}")
        if not (math.isfinite(sigma_s_prime) and sigma_s_prime >= 0):
            raise InputError(f"sigma_s_prime must be finite and >= 0, got {sigma_s_prime}")
        return cls(sigma_s=sigma_s_prime / (1.0 - g), sigma_a=sigma_a, g=g, n=n, thickness_mm=thickness_mm)

    def replace(self, **changes) -> Medium:
        """A copy with some fields changed (validated again), as :func:`dataclasses.replace`."""
        unknown = set(changes) - set(_FIELDS)
        if unknown:
            raise InputError(f"unknown Medium field(s) {sorted(unknown)}; fields are {list(_FIELDS)}")
        return dataclasses.replace(self, **changes)

    # ------------------------------------------------------------ plain data
    def to_dict(self) -> dict:
        """JSON-ready fields; a semi-infinite medium has ``thickness_mm: None``."""
        return {
            "sigma_s": self.sigma_s,
            "sigma_a": self.sigma_a,
            "g": self.g,
            "n": self.n,
            "thickness_mm": None if self.semi_infinite else self.thickness_mm,
        }

    @classmethod
    def from_dict(cls, data) -> Medium:
        """Inverse of :meth:`to_dict` (``n`` and ``thickness_mm`` optional; ``None`` = semi-infinite)."""
        try:
            keys = set(data)
        except TypeError:
            raise InputError(f"a medium must be a mapping of {list(_FIELDS)}, got {data!r}") from None
        unknown = keys - set(_FIELDS)
        if unknown:
            raise InputError(f"unknown Medium field(s) {sorted(unknown)}; fields are {list(_FIELDS)}")
        missing = [k for k in ("sigma_s", "sigma_a", "g") if k not in keys]
        if missing:
            raise InputError(f"medium is missing {missing}")
        kw = dict(data)
        if kw.get("thickness_mm", 0.0) is None:
            kw["thickness_mm"] = math.inf
        return cls(**kw)


def as_medium(value) -> Medium:
    """``value`` if it is a :class:`Medium`; otherwise a ``TypeError`` saying how to build one.

    Parameters
    ----------
    value : Medium
        The medium (anything else is refused with a message saying how to build one).

    Returns
    -------
    Medium
        ``value`` itself.

    See Also
    --------
    Medium : the optical constants.

    Examples
    --------
    >>> m = Medium(sigma_s=1.0, sigma_a=0.01, g=0.9)
    >>> as_medium(m) is m
    True
    """
    if isinstance(value, Medium):
        return value
    raise TypeError(
        f"expected a planeray.Medium, got {type(value).__name__} {value!r}; build one with "
        "Medium(sigma_s=..., sigma_a=..., g=..., n=..., thickness_mm=...)"
    )
