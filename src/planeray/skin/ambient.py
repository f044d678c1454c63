"""Ambient light in the camera's band: from illuminance (lux) to the camera model's ``ambient_e_per_us``.

The simulated camera counts ambient light as ``ambient_e_per_us * t_e * albedo`` electrons
(:class:`planeray.camera.CameraModel`).  A light source is stated by its illuminance (lux,
what a light meter reads) and its spectrum; what the camera sees is the irradiance in its
band (a bandpass filter of ``filter_fwhm_nm`` around the laser line, 10 nm by default):

    E_band = lux / (683 lm/W * int V(l) S(l) dl) * int_band S(l) dl          [W/m^2]

with ``S`` the relative spectrum and ``V`` the CIE photopic luminosity function (the Gaussian
approximation ``V(l) = 1.019 exp(-285.4 (l/um - 0.559)^2)``, within a few percent of the
CIE 1924 table over 450-650 nm).  The camera's electrons scale with irradiance whatever the
source, so the **projector** fixes the scale: ``laser_electrons`` electrons per frame-pass
come from the projector's time-averaged irradiance ``E_proj`` (its optical power over the
field it lights) spread over one frame period ``T_f``; hence

    ambient_e_per_us = laser_electrons / T_f[us] * E_band / E_proj.

Assumptions, stated where they are used and recorded in the results: the projector puts
``projector_power_w`` = 30 mW of laser light (the PicoPro class of laser pico-projector:
some tens of lumens, one laser line per colour) onto a 0.36 x 0.20 m field at 0.5 m (the
paper's working distance; 16:9 throw), so ``E_proj`` = 0.42 W/m^2 time-averaged; the same
power is assumed for an 850 nm laser line.

Spectra: daylight/sunlight is a 5778 K blackbody (the solar photosphere; the real spectrum
at ground level has absorption bands, the 850 nm window is clear); room light and the
surgical lamp are white LEDs: a blue pump at 450 nm (sigma 10 nm, 0.45 of the phosphor's peak)
plus a phosphor band at 580 nm (sigma 70 nm), whose luminous efficacy of radiation, 324 lm/W,
is typical of 4000 K phosphor-converted LEDs (about 300-350 lm/W); the 5778 K blackbody gives
92 lm/W (93 lm/W for 5800 K in the literature).  LEDs have almost nothing at 850 nm: the
advantage a near-infrared line has indoors is real and shows in the numbers.

Levels (:data:`AMBIENT_LEVELS`): dim room 100 lx; office 500 lx (EN 12464-1 for desk work);
surgical lamp 40,000 and 160,000 lx (IEC 60601-2-41's range for the central illuminance of a
surgical luminaire); overcast daylight 10,000 lx; direct sunlight 100,000 lx.

References
----------
.. [1] CIE 1924 photopic luminosity function; the Gaussian fit is from J. Schanda (ed.),
   "Colorimetry: Understanding the CIE System", Wiley 2007 (approximations of V(lambda)).
.. [2] IEC 60601-2-41:2009, particular requirements for surgical luminaires (Ec 40-160 klx).
.. [3] EN 12464-1:2021, lighting of indoor work places (500 lx for writing and reading).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "AMBIENT_LEVELS",
    "PROJECTOR_POWER_W",
    "PROJECTOR_FIELD_M2",
    "luminosity",
    "relative_spectrum",
    "band_irradiance_w_m2",
    "ambient_e_per_us",
    "ambient_table",
]

#: Laser power delivered to the scene (W) and the field it covers at 0.5 m (m^2).
PROJECTOR_POWER_W = 0.030
PROJECTOR_FIELD_M2 = 0.36 * 0.20
#: Projector frame period (60 Hz).
FRAME_PERIOD_US = 1e6 / 60.0
#: Name -> (illuminance in lux, spectrum).
AMBIENT_LEVELS = {
    "dark": (0.0, "led"),
    "dim room": (100.0, "led"),
    "office": (500.0, "led"),
    "overcast daylight": (10_000.0, "sun"),
    "surgical lamp": (40_000.0, "led"),
    "sunlight": (100_000.0, "sun"),
    "surgical lamp (max)": (160_000.0, "led"),
}
_GRID_NM = np.arange(300.0, 1200.5, 0.5)


def luminosity(wavelength_nm) -> np.ndarray:
    """CIE photopic luminosity ``V(lambda)`` (Gaussian approximation; peak 1 near 555 nm)."""
    lum = np.asarray(wavelength_nm, float) * 1e-3
    return 1.019 * np.exp(-285.4 * (lum - 0.559) ** 2)


def relative_spectrum(kind: str, wavelength_nm) -> np.ndarray:
    """Relative spectral power of ``"sun"`` (5778 K blackbody) or ``"led"`` (phosphor white)."""
    lam = np.asarray(wavelength_nm, float)
    if kind == "sun":
        x = 1.4388e7 / (lam * 5778.0)  # hc / (lambda k T), lambda in nm
        return (lam / 500.0) ** -5 / np.expm1(x)
    if kind == "led":
        return 0.45 * np.exp(-0.5 * ((lam - 450.0) / 10.0) ** 2) + np.exp(-0.5 * ((lam - 580.0) / 70.0) ** 2)
    raise ValueError(f"unknown spectrum {kind!r}: sun or led")


def band_irradiance_w_m2(lux: float, kind: str, wavelength_nm: float, *, filter_fwhm_nm: float = 10.0) -> float:
    """Irradiance (W/m^2) in a box band of ``filter_fwhm_nm`` around ``wavelength_nm`` for ``lux``.

    Parameters
    ----------
    lux : float
        Illuminance, lux.
    kind : {"sun", "led", ...}
        The light's spectrum.
    wavelength_nm : float
        Centre of the band, nm.
    filter_fwhm_nm : float
        Width of the band, nm.

    Returns
    -------
    float
        W/m^2 in the band.

    See Also
    --------
    ambient_e_per_us : in the camera's electrons.

    Examples
    --------
    >>> round(band_irradiance_w_m2(100_000, "sun", 638.0), 1)
    12.5
    >>> band_irradiance_w_m2(500, "led", 850.0) < 1e-4
    True
    """
    s = relative_spectrum(kind, _GRID_NM)
    step = _GRID_NM[1] - _GRID_NM[0]
    lumens_per_unit = 683.0 * float(np.sum(luminosity(_GRID_NM) * s)) * step
    half = 0.5 * float(filter_fwhm_nm)
    band = np.linspace(float(wavelength_nm) - half, float(wavelength_nm) + half, 201)
    return float(float(lux) / lumens_per_unit * float(np.trapezoid(relative_spectrum(kind, band), band)))


def ambient_e_per_us(
    lux: float,
    kind: str,
    wavelength_nm: float,
    *,
    laser_electrons: float = 6000.0,
    filter_fwhm_nm: float = 10.0,
    projector_power_w: float = PROJECTOR_POWER_W,
    field_m2: float = PROJECTOR_FIELD_M2,
) -> float:
    """The camera model's ``ambient_e_per_us`` for an ambient light (see the module notes).

    Parameters
    ----------
    lux : float
        Illuminance of the ambient light, lux.
    kind : {"sun", "led", ...}
        Its spectrum.
    wavelength_nm : float
        The camera filter's centre, nm.
    laser_electrons : float
        The camera model's electrons per frame from the laser.
    filter_fwhm_nm : float
        Width of the camera's filter, nm.
    projector_power_w : float
        The laser projector's optical power, W.
    field_m2 : float
        Area the projector lights, m^2.

    Returns
    -------
    float
        Electrons per microsecond of exposure for albedo 1.

    See Also
    --------
    ambient_table : the standard levels.

    Examples
    --------
    >>> round(ambient_e_per_us(100_000, "sun", 638.0), 1)
    10.8
    """
    e_proj = float(projector_power_w) / float(field_m2)
    e_band = band_irradiance_w_m2(lux, kind, wavelength_nm, filter_fwhm_nm=filter_fwhm_nm)
    return float(laser_electrons) / FRAME_PERIOD_US * e_band / e_proj


def ambient_table(wavelength_nm: float, *, laser_electrons: float = 6000.0, filter_fwhm_nm: float = 10.0) -> list:
    """One row per :data:`AMBIENT_LEVELS` entry: lux, spectrum, W/m^2 in band, ``ambient_e_per_us``.

    Parameters
    ----------
    wavelength_nm : float
        The camera filter's centre, nm.
    laser_electrons : float
        The camera model's electrons per frame from the laser.
    filter_fwhm_nm : float
        Width of the camera's filter, nm.

    Returns
    -------
    list of dict
        One row per level.

    See Also
    --------
    ambient_e_per_us : one level.

    Examples
    --------
    >>> rows = ambient_table(850)
    >>> len(rows) == len(AMBIENT_LEVELS), sorted(rows[0])[:2]
    (True, ['ambient_e_per_us', 'band_w_m2'])
    """
    rows = []
    for name, (lux, kind) in AMBIENT_LEVELS.items():
        rows.append(
            {
                "name": name,
                "lux": lux,
                "spectrum": kind,
                "wavelength_nm": float(wavelength_nm),
                "band_w_m2": band_irradiance_w_m2(lux, kind, wavelength_nm, filter_fwhm_nm=filter_fwhm_nm),
                "ambient_e_per_us": ambient_e_per_us(
                    lux, kind, wavelength_nm, laser_electrons=laser_electrons, filter_fwhm_nm=filter_fwhm_nm
                ),
            }
        )
    return rows
