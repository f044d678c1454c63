"""Optical constants of the white materials of the paper's recognition experiment (Sec. 8, Fig. 10).

Kubo et al. image five containers -- fat-free milk, 2 % milk, whole milk, toothpaste and
liquid soap -- that look alike in an ordinary photograph and tell them apart by their delay
profiles.  This module holds the homogeneous-medium parameters planeray simulates them
with, each with its source, as :class:`planeray.medium.Medium` values per colour channel
(the simulated projector draws its line in one laser colour; red by default).

Two published sets for the milks, which disagree (a robustness check for the recognition,
see :mod:`planeray.experiments.materials`):

``"narasimhan"`` (default)
    Narasimhan, Gupta, Donner, Ramamoorthi, Nayar & Jensen 2006 [1]_, measured by dilution
    (coefficients of the undiluted media in mm^-1, Henyey-Greenstein ``g`` per channel,
    refractive index 1.33).  Fat-free milk is their "lowfat milk", 2 % milk their "reduced
    milk" (the US name of 2 % milk) and whole milk their "regular milk".  The reduced
    scattering ``sigma_s (1 - g)`` of these values is what the pbrt-v3 table [3]_ lists for
    the same entries (0.892/1.514/2.532 mm^-1 for lowfat milk), a check of the transcription.
``"jensen"``
    Jensen, Marschner, Levoy & Hanrahan 2001 [2]_ (reduced scattering ``sigma_s'`` and
    ``sigma_a`` in mm^-1, relative index 1.3): skim milk (fat-free) and whole milk.  The
    paper gives no ``g`` (the dipole needs only ``sigma_s'``), so the Monte Carlo uses the
    ``g`` of the corresponding Narasimhan milk and ``sigma_s = sigma_s' / (1 - g)`` (the
    similarity relation).  It has no 2 % milk: its coefficients are interpolated linearly
    in fat content between skim (0.1 % fat) and whole milk (3.25 %) -- light scattering of
    milk grows with its fat globules, so ``sigma_s'`` and ``sigma_a`` move with the fat
    fraction; this is a modelling choice, not a measurement.  Jensen's whole milk
    scatters about half as strongly as Narasimhan's regular milk (2.55 vs 4.55 mm^-1 in
    red): different samples, wavelengths and fitting models.

Toothpaste and liquid soap have no published coefficients; the values below are chosen
to be physically plausible and are the same in both sets:

toothpaste
    An opaque white paste: abrasives (calcium carbonate, hydrated silica) and titanium
    dioxide pigment at tens of percent by weight, particles of about a micrometre -- a
    white paint more than a liquid.  Strongly scattering and nearly opaque:
    ``sigma_s' ~ 16 mm^-1`` (transport mean free path 0.06 mm, like a white paint film or
    a dense TiO2 suspension), moderately forward scattering ``g = 0.6`` (Mie scattering of
    micrometre particles), a little absorption (``sigma_a ~ 0.02 mm^-1``, an off-white
    albedo ~0.8), index 1.45 (glycerol/sorbitol binder).  Its diffusion length
    ``1 / sigma_tr ~ 1 mm`` (3 projector rows at 0.3 mm): a delay profile barely wider
    than a diffuse surface.
liquid soap
    A pearly (pearlescent) hand soap: a clear surfactant solution with a few percent of
    glycol distearate platelets that give it a soft sheen.  Weakly scattering:
    ``sigma_s' = 0.2 mm^-1`` (transport mean free path 5 mm, four times that of fat-free
    milk), ``g = 0.8`` (platelets of several micrometres scatter forward), little
    absorption (``sigma_a = 0.004 mm^-1``, a slightly tinted soap), index 1.38 (a
    concentrated surfactant/glycerol solution).  Light travels centimetres in it, so the
    depth of the container matters: the soap is a 30 mm deep layer (light leaving its
    bottom is lost), while the milks and the toothpaste, whose diffusion lengths are
    1-11 mm, are semi-infinite.

The per-channel values of the two chosen materials follow the milks' trend (scattering
grows slightly from red to blue, absorption grows more).

References
----------
.. [1] S. G. Narasimhan, M. Gupta, C. Donner, R. Ramamoorthi, S. K. Nayar, H. W. Jensen,
   "Acquiring scattering properties of participating media by dilution", ACM Trans.
   Graph. 25(3) (SIGGRAPH 2006), 1003-1012.
.. [2] H. W. Jensen, S. R. Marschner, M. Levoy, P. Hanrahan, "A practical model for
   subsurface light transport", SIGGRAPH 2001, Fig. 5 table of measured coefficients.
.. [3] M. Pharr, W. Jakob, G. Humphreys, "Physically Based Rendering", 3rd ed., 2016,
   ``src/core/medium.cpp`` (``SubsurfaceParameterTable``).
.. [4] Kubo et al., "Programmable Non-Epipolar Indirect Light Transport: Capture and
   Analysis", IEEE TVCG 2019, Sec. 8 and Fig. 10.
"""

from __future__ import annotations

import math

from .errors import InputError
from .medium import Medium

__all__ = [
    "MATERIAL_CLASSES",
    "BACKGROUND_CLASS",
    "UNLABELLED",
    "CLASS_NAMES",
    "CHANNELS",
    "OPTICAL_SOURCES",
    "MATERIAL_KEYS",
    "SOAP_DEPTH_MM",
    "material_medium",
    "material_media",
    "optical_table",
]

#: Class ids of the five materials (label images hold these integers; 0 = unlabelled).
MATERIAL_CLASSES = {1: "fat-free milk", 2: "2% milk", 3: "whole milk", 4: "toothpaste", 5: "liquid soap"}
#: Class id of everything outside the containers (the table).
BACKGROUND_CLASS = 6
#: Label value of pixels without a label (left out of training and scoring).
UNLABELLED = 0
#: Every documented class id and its name.
CLASS_NAMES = {**MATERIAL_CLASSES, BACKGROUND_CLASS: "background"}
#: Short keys of the materials, by class id (used in parameters and file names).
MATERIAL_KEYS = {1: "fat_free_milk", 2: "milk_2pct", 3: "whole_milk", 4: "toothpaste", 5: "liquid_soap"}
#: Colour channels of the tables (the projector's laser lines).
CHANNELS = ("red", "green", "blue")
#: Names of the optical data sets.
OPTICAL_SOURCES = ("narasimhan", "jensen")
#: Depth of the liquid soap layer (mm): light that crosses it is lost at the bottom.
SOAP_DEPTH_MM = 30.0

_N_MILK_NARASIMHAN = 1.33
_N_MILK_JENSEN = 1.3

# Narasimhan et al. 2006 [1]: sigma_s, sigma_a (mm^-1) and g, per RGB channel.
_NARASIMHAN = {
    1: dict(sigma_s=(13.12, 15.44, 17.96), sigma_a=(0.00287, 0.00575, 0.0115), g=(0.932, 0.902, 0.859)),  # lowfat
    2: dict(sigma_s=(13.73, 15.60, 17.80), sigma_a=(0.00256, 0.00511, 0.01278), g=(0.819, 0.797, 0.746)),  # reduced
    3: dict(sigma_s=(18.21, 20.38, 22.37), sigma_a=(0.00153, 0.0046, 0.01993), g=(0.750, 0.714, 0.681)),  # regular
}

# Jensen et al. 2001 [2]: sigma_s' and sigma_a (mm^-1) per RGB channel.
_JENSEN_SKIM = dict(sigma_s_prime=(0.70, 1.22, 1.90), sigma_a=(0.0014, 0.0025, 0.0142))
_JENSEN_WHOLE = dict(sigma_s_prime=(2.55, 3.21, 3.77), sigma_a=(0.0011, 0.0024, 0.014))
_FAT_PCT = {1: 0.1, 2: 2.0, 3: 3.25}  # fat content of skim, 2 % and whole milk

# The two materials without published coefficients (see the module docstring).
_CHOSEN = {
    4: dict(sigma_s_prime=(16.0, 17.0, 18.0), sigma_a=(0.020, 0.025, 0.035), g=0.6, n=1.45, thickness_mm=math.inf),
    5: dict(sigma_s_prime=(0.20, 0.22, 0.25), sigma_a=(0.004, 0.006, 0.010), g=0.8, n=1.38, thickness_mm=SOAP_DEPTH_MM),
}


def _channel_index(channel: str) -> int:
    if channel not in CHANNELS:
        raise InputError(f"unknown colour channel {channel!r}; choose one of {', '.join(CHANNELS)}")
    return CHANNELS.index(channel)


def _class_id(material) -> int:
    if isinstance(material, str):
        for cid, key in MATERIAL_KEYS.items():
            if material in (key, MATERIAL_CLASSES[cid]):
                return cid
        raise InputError(f"unknown material {material!r}; choose one of {', '.join(MATERIAL_KEYS.values())}")
    cid = int(material)
    if cid not in MATERIAL_CLASSES:
        raise InputError(f"unknown material class {material!r}; classes are {sorted(MATERIAL_CLASSES)}")
    return cid


def material_medium(material, *, source: str = "narasimhan", channel: str = "red") -> Medium:
    """The :class:`~planeray.medium.Medium` of one material.

    Parameters
    ----------
    material : int or str
        Class id (1-5, :data:`MATERIAL_CLASSES`), key (:data:`MATERIAL_KEYS`) or name.
    source : {"narasimhan", "jensen"}
        Optical data set of the milks (the module docstring says where each comes from).
    channel : {"red", "green", "blue"}
        Colour of the projector's line.

    Returns
    -------
    Medium

    See Also
    --------
    material_media : all five.

    Examples
    --------
    >>> m = material_medium("fat_free_milk")
    >>> m.sigma_s, m.sigma_a, m.g, m.n
    (13.12, 0.00287, 0.932, 1.33)
    >>> round(m.sigma_s_prime, 4)  # pbrt-v3 lists 0.89187 for Narasimhan's lowfat milk
    0.8922
    >>> round(material_medium(3, source="jensen").sigma_s_prime, 6)
    2.55
    >>> material_medium("liquid_soap").thickness_mm
    30.0
    """
    cid = _class_id(material)
    c = _channel_index(channel)
    if source not in OPTICAL_SOURCES:
        raise InputError(f"unknown optical data source {source!r}; choose one of {', '.join(OPTICAL_SOURCES)}")
    if cid in _CHOSEN:
        p = _CHOSEN[cid]
        return Medium.from_reduced(
            p["sigma_s_prime"][c], p["sigma_a"][c], g=p["g"], n=p["n"], thickness_mm=p["thickness_mm"]
        )
    g = _NARASIMHAN[cid]["g"][c]
    if source == "narasimhan":
        p = _NARASIMHAN[cid]
        return Medium(sigma_s=p["sigma_s"][c], sigma_a=p["sigma_a"][c], g=g, n=_N_MILK_NARASIMHAN)
    f = (_FAT_PCT[cid] - _FAT_PCT[1]) / (_FAT_PCT[3] - _FAT_PCT[1])
    sp = (1 - f) * _JENSEN_SKIM["sigma_s_prime"][c] + f * _JENSEN_WHOLE["sigma_s_prime"][c]
    sa = (1 - f) * _JENSEN_SKIM["sigma_a"][c] + f * _JENSEN_WHOLE["sigma_a"][c]
    return Medium.from_reduced(round(sp, 12), round(sa, 12), g=g, n=_N_MILK_JENSEN)


def material_media(*, source: str = "narasimhan", channel: str = "red") -> dict[int, Medium]:
    """The five media by class id (:func:`material_medium` for each).

    Parameters
    ----------
    source : {"narasimhan", "jensen"}
        The published constants of the milks (Narasimhan et al. 2006 or Jensen et al. 2001).
    channel : {"red", "green", "blue"}
        The laser line.

    Returns
    -------
    dict of int to Medium
        Class id -> medium (1/mm coefficients).

    See Also
    --------
    material_medium : one material.
    optical_table : as table rows.

    Examples
    --------
    >>> media = material_media()
    >>> sorted(media), round(media[3].sigma_s_prime, 2)  # whole milk's reduced scattering, 1/mm
    ([1, 2, 3, 4, 5], 4.6)
    """
    return {cid: material_medium(cid, source=source, channel=channel) for cid in MATERIAL_CLASSES}


def optical_table(*, source: str = "narasimhan", channel: str = "red") -> list[dict]:
    """The media as JSON-ready rows with derived lengths (for reports and the README).

    Each row: ``class_id``, ``name``, the medium's fields, ``sigma_s_prime``,
    ``transport_mfp_mm`` and the diffusion length ``1 / sigma_tr`` in mm
    (``sigma_tr = sqrt(3 sigma_a (sigma_a + sigma_s'))``).

    Parameters
    ----------
    source : {"narasimhan", "jensen"}
        The published constants of the milks.
    channel : {"red", "green", "blue"}
        The laser line.

    Returns
    -------
    list of dict
        One row per medium.

    See Also
    --------
    material_media : the media themselves.

    Examples
    --------
    >>> rows = optical_table()
    >>> len(rows), "name" in rows[0]
    (5, True)
    """
    rows = []
    for cid, m in material_media(source=source, channel=channel).items():
        sigma_tr = math.sqrt(3.0 * m.sigma_a * (m.sigma_a + m.sigma_s_prime))
        rows.append(
            {
                "class_id": cid,
                "name": MATERIAL_CLASSES[cid],
                **m.to_dict(),
                "sigma_s_prime": m.sigma_s_prime,
                "transport_mfp_mm": m.transport_mfp_mm,
                "diffusion_length_mm": 1.0 / sigma_tr if sigma_tr > 0 else math.inf,
            }
        )
    return rows
