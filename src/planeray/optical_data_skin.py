"""Optical constants of human skin and venous blood at the projector's red line (638 nm) and at 850 nm.

The ``skin`` scene (:mod:`planeray.scenes.skin`) is a stack of three layers -- epidermis,
dermis, subcutaneous fat -- with blood-filled cylinders (veins) in it.  Every coefficient
is in mm^-1; scattering is Henyey-Greenstein with ``g = 0.9`` (Jacques 2013 [1]_: tissue
``g`` is 0.8-0.95 in the red and near infrared) and every layer has index ``n = 1.4``
against air (Jacques 2013 [1]_, Sec. 2; the layers are index matched to one another).

Formulas (Jacques 2013 [1]_, Sec. 4 "generic tissue" and its Table 2):

epidermis
    ``mu_a = M mu_a,mel(lambda) + W mu_a,water``: melanosome volume fraction ``M`` (the
    skin tone, :data:`SKIN_TONES`), ``mu_a,mel = 6.6e11 lambda^-3.33 cm^-1`` (lambda in nm;
    Jacques' melanosome spectrum, [1]_ and [3]_), water fraction ``W = 0.5``.
dermis
    ``mu_a = B mu_a,blood(S) + W mu_a,water``, blood volume fraction ``B = 0.2 %``, oxygen
    saturation ``S = 0.7``, water ``W = 0.65``.
blood
    ``mu_a,blood(S) = S mu_a,oxy + (1 - S) mu_a,deoxy`` of whole blood (150 g/L Hb).  The
    venous value (``S = 0.7``) at each line is the one quoted from [1]_ (0.892 and
    0.512 mm^-1); the split into oxy and deoxy follows the ratio of Prahl's tabulated molar
    extinction coefficients [2]_ (Gratzer/Kollias, 640 nm: 442 / 4345.2 cm^-1/M; 850 nm:
    1058 / 691.32 cm^-1/M), so changing ``S`` moves ``mu_a`` as the haemoglobin spectra do.
    Blood scattering: ``mu_s`` 7.84 / 5.88 mm^-1 (after [1]_), ``g = 0.9``.
water
    Hale & Querry 1973 [4]_: 0.00031 mm^-1 at 638 nm, 0.0043 mm^-1 at 850 nm.
scattering of epidermis and dermis
    ``mu_s`` (31.4 / 23.5 and 22.5 / 12.6 mm^-1 at 638 / 850 nm, ``g = 0.9``),
    the values of the generic-skin scattering power laws of [1]_.
subcutaneous fat
    Bashkatov et al. 2005 [5]_: ``mu_s' = 2.7 mm^-1`` and ``mu_a = 0.19 mm^-1`` at 600 nm
    (the values quoted there).  ``mu_s'`` is scaled as ``lambda^-0.68``; ``mu_a`` at 600 nm
    is mostly the blood in the fat, so it is carried to 638 and 850 nm with the absorption
    spectrum of blood at ``S = 0.7`` (Prahl [2]_, 600 nm: 3200 / 14677.2 cm^-1/M; a factor
    0.24 at 638 nm and 0.14 at 850 nm) plus water (``W = 0.2``): 0.046 and 0.028 mm^-1.
    This transfer is our modelling step, not a published value at those lines.

The published numbers these constants reproduce are checked in ``tests/test_skin.py``
(``test_optical_constants_match_issue``).

References
----------
.. [1] S. L. Jacques, "Optical properties of biological tissues: a review", Phys. Med.
   Biol. 58, R37-R61, 2013.
.. [2] S. Prahl, "Tabulated molar extinction coefficient for hemoglobin in water",
   omlc.org/spectra/hemoglobin (Gratzer and Kollias data), 1999.
.. [3] S. L. Jacques, "Skin optics", Oregon Medical Laser Center News, 1998 (melanosome
   absorption ``6.6e11 lambda^-3.33 cm^-1``).
.. [4] G. M. Hale, M. R. Querry, "Optical constants of water in the 200-nm to 200-um
   wavelength region", Appl. Opt. 12, 555-563, 1973.
.. [5] A. N. Bashkatov, E. A. Genina, V. I. Kochubey, V. V. Tuchin, "Optical properties of
   human skin, subcutaneous and mucous tissues in the wavelength range from 400 to 2000
   nm", J. Phys. D 38, 2543-2555, 2005.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from .errors import InputError
from .medium import Medium

__all__ = [
    "SKIN_WAVELENGTHS_NM",
    "SKIN_TONES",
    "SKIN_G",
    "SKIN_N",
    "SkinLayers",
    "melanosome_mu_a",
    "blood_mu_a",
    "blood_medium",
    "epidermis_medium",
    "dermis_medium",
    "fat_medium",
    "skin_layers",
    "skin_model",
    "LAYER_NAMES",
    "tone_fraction",
]

#: Wavelengths with tabulated constants: the projector's red laser line and the near infrared.
SKIN_WAVELENGTHS_NM = (638, 850)
#: Skin tones: melanosome volume fraction of the epidermis (Jacques 1998 [3]_: 1.3-6.3 % light
#: to moderately pigmented adults, 18-43 % darkly pigmented).
SKIN_TONES = {
    "very_fair": 0.015,
    "fair": 0.03,
    "medium": 0.08,
    "olive": 0.13,
    "brown": 0.2,
    "dark": 0.3,
}
SKIN_G = 0.9
SKIN_N = 1.4

_WATER_MU_A = {638: 0.00031, 850: 0.0043}  # Hale & Querry 1973 [4]
_VENOUS_MU_A = {638: 0.892, 850: 0.512}  # S = 0.7 whole blood, after Jacques 2013 [1]
_VENOUS_S = 0.7
_HB_EPSILON = {638: (442.0, 4345.2), 850: (1058.0, 691.32)}  # Prahl [2]: (HbO2, Hb), cm^-1/M
_BLOOD_MU_S = {638: 7.84, 850: 5.88}
_EPIDERMIS_MU_S = {638: 31.4, 850: 23.5}
_DERMIS_MU_S = {638: 22.5, 850: 12.6}
_FAT_MU_S_PRIME_600 = 2.7
_FAT_B = 0.68
_FAT_MU_A_600 = 0.19
_HB_EPSILON_600 = (3200.0, 14677.2)  # Prahl [2], 600 nm: (HbO2, Hb), cm^-1/M
_FAT_WATER = 0.2
_EPIDERMIS_WATER = 0.5
_DERMIS_BLOOD = 0.002
_DERMIS_S = 0.7
_DERMIS_WATER = 0.65


def _line(wavelength_nm) -> int:
    w = float(wavelength_nm)
    for line in SKIN_WAVELENGTHS_NM:
        if abs(w - line) < 0.5:
            return line
    raise InputError(f"skin optics are tabulated at {SKIN_WAVELENGTHS_NM} nm, not {wavelength_nm}")


def tone_fraction(tone) -> float:
    """Melanosome volume fraction of a tone: a name of :data:`SKIN_TONES` or a fraction in ``[0, 0.5]``.

    Parameters
    ----------
    tone : str or float
        ``"very_fair"``, ``"fair"``, ``"medium"``, ``"olive"``, ``"brown"``, ``"dark"`` or a fraction.

    Returns
    -------
    float
        Melanosome volume fraction.

    See Also
    --------
    epidermis_medium : uses it.

    Examples
    --------
    >>> tone_fraction("fair"), tone_fraction(0.05)
    (0.03, 0.05)
    """
    if isinstance(tone, str):
        if tone not in SKIN_TONES:
            raise InputError(f"unknown skin tone {tone!r}; choose one of {', '.join(SKIN_TONES)} or a fraction")
        return SKIN_TONES[tone]
    m = float(tone)
    if not 0.0 <= m <= 0.5:
        raise InputError(f"melanosome fraction must be in [0, 0.5], got {tone}")
    return m


def melanosome_mu_a(wavelength_nm) -> float:
    """Absorption of a melanosome, ``6.6e11 lambda^-3.33 cm^-1`` (Jacques [3]_), in mm^-1.

    Parameters
    ----------
    wavelength_nm : float
        The laser line, nm (638 or 850 in the paper's experiments).

    Returns
    -------
    float
        Absorption coefficient, 1/mm.

    See Also
    --------
    epidermis_medium : uses it.

    Examples
    --------
    >>> round(melanosome_mu_a(638), 1)  # 1/mm
    30.2
    """
    return 6.6e11 * float(wavelength_nm) ** -3.33 / 10.0


def blood_mu_a(wavelength_nm, saturation=_VENOUS_S) -> float:
    """Absorption of whole blood (150 g/L) at oxygen saturation ``saturation``, mm^-1.

    ``S mu_oxy + (1 - S) mu_deoxy``, scaled so ``S = 0.7`` gives the published venous value (Jacques 2013 [1]_).

    Parameters
    ----------
    wavelength_nm : float
        The laser line, nm (638 or 850 in the paper's experiments).
    saturation : float
        Oxygen saturation, 0 to 1.

    Returns
    -------
    float
        Absorption coefficient, 1/mm.

    See Also
    --------
    blood_medium : the blood as a medium.

    Examples
    --------
    >>> round(blood_mu_a(638), 3), round(blood_mu_a(850), 3)  # 1/mm, venous (saturation 0.7)
    (0.892, 0.512)
    """
    line = _line(wavelength_nm)
    s = float(saturation)
    if not 0.0 <= s <= 1.0:
        raise InputError(f"oxygen saturation must be in [0, 1], got {saturation}")
    eo, ed = _HB_EPSILON[line]
    scale = _VENOUS_MU_A[line] / (_VENOUS_S * eo + (1.0 - _VENOUS_S) * ed)
    return scale * (s * eo + (1.0 - s) * ed)


def blood_medium(wavelength_nm, saturation=_VENOUS_S) -> Medium:
    """Venous blood as a :class:`Medium` (index matched to the tissue around it).

    Parameters
    ----------
    wavelength_nm : float
        The laser line, nm (638 or 850 in the paper's experiments).
    saturation : float
        Oxygen saturation, 0 to 1.

    Returns
    -------
    Medium

    See Also
    --------
    blood_mu_a : its absorption.

    Examples
    --------
    >>> m = blood_medium(850)
    >>> round(m.sigma_a, 3), m.g
    (0.512, 0.9)
    """
    line = _line(wavelength_nm)
    return Medium(sigma_s=_BLOOD_MU_S[line], sigma_a=blood_mu_a(line, saturation), g=SKIN_G, n=SKIN_N)


def epidermis_medium(wavelength_nm, melanin_fraction, thickness_mm=0.1) -> Medium:
    """Epidermis with melanosome fraction ``melanin_fraction`` (Jacques 2013 [1]_).

    Parameters
    ----------
    wavelength_nm : float
        The laser line, nm (638 or 850 in the paper's experiments).
    melanin_fraction : float
        Melanosome volume fraction (:func:`tone_fraction`).
    thickness_mm : float
        Thickness, mm.

    Returns
    -------
    Medium

    See Also
    --------
    skin_layers : the whole skin.

    Examples
    --------
    >>> m = epidermis_medium(638, tone_fraction("fair"))
    >>> round(m.sigma_a, 3)  # 1/mm
    0.905
    """
    line = _line(wavelength_nm)
    m = tone_fraction(melanin_fraction)
    mu_a = m * melanosome_mu_a(line) + _EPIDERMIS_WATER * _WATER_MU_A[line]
    return Medium(sigma_s=_EPIDERMIS_MU_S[line], sigma_a=mu_a, g=SKIN_G, n=SKIN_N, thickness_mm=thickness_mm)


def dermis_medium(wavelength_nm, thickness_mm=1.5, *, blood_fraction=_DERMIS_BLOOD, saturation=_DERMIS_S) -> Medium:
    """Dermis with blood fraction ``blood_fraction`` at saturation ``saturation`` (Jacques 2013 [1]_).

    Parameters
    ----------
    wavelength_nm : float
        The laser line, nm (638 or 850 in the paper's experiments).
    thickness_mm : float
        Thickness, mm.
    blood_fraction : float
        Blood volume fraction.
    saturation : float
        The blood's oxygen saturation.

    Returns
    -------
    Medium

    See Also
    --------
    skin_layers : the whole skin.

    Examples
    --------
    >>> round(dermis_medium(638).sigma_a, 4)  # 1/mm
    0.002
    """
    line = _line(wavelength_nm)
    mu_a = float(blood_fraction) * blood_mu_a(line, saturation) + _DERMIS_WATER * _WATER_MU_A[line]
    return Medium(sigma_s=_DERMIS_MU_S[line], sigma_a=mu_a, g=SKIN_G, n=SKIN_N, thickness_mm=thickness_mm)


def fat_medium(wavelength_nm, thickness_mm=8.0) -> Medium:
    """Subcutaneous fat (Bashkatov et al. 2005 [5]_).

    Parameters
    ----------
    wavelength_nm : float
        The laser line, nm (638 or 850 in the paper's experiments).
    thickness_mm : float
        Thickness, mm.

    Returns
    -------
    Medium

    See Also
    --------
    skin_layers : the whole skin.

    Examples
    --------
    >>> m = fat_medium(638)
    >>> m.thickness_mm
    8.0
    """
    line = _line(wavelength_nm)
    mu_s_prime = _FAT_MU_S_PRIME_600 * (line / 600.0) ** -_FAT_B
    eo, ed = _HB_EPSILON[line]
    eo6, ed6 = _HB_EPSILON_600
    blood_scale = (_VENOUS_S * eo + (1 - _VENOUS_S) * ed) / (_VENOUS_S * eo6 + (1 - _VENOUS_S) * ed6)
    mu_a = _FAT_MU_A_600 * blood_scale + _FAT_WATER * _WATER_MU_A[line]
    return Medium.from_reduced(mu_s_prime, mu_a, g=SKIN_G, n=SKIN_N, thickness_mm=thickness_mm)


@dataclass(frozen=True)
class SkinLayers:
    """The layer stack of the skin, top first, and the blood of its veins.

    Parameters
    ----------
    wavelength_nm : int
        The wavelength, nm.
    layers : tuple of Medium
        Epidermis, dermis, fat, top first (``thickness_mm`` each).
    blood : Medium
        The veins' blood.

    See Also
    --------
    skin_layers : builds one.

    Examples
    --------
    >>> layers = skin_layers(638, "fair")
    >>> [round(layer.thickness_mm, 2) for layer in layers.layers][:2], layers.wavelength_nm
    ([0.1, 1.5], 638)
    """

    wavelength_nm: int
    layers: tuple  # of Medium, each with its thickness
    blood: Medium

    @property
    def depth_mm(self) -> float:
        return float(sum(m.thickness_mm for m in self.layers))

    def to_json(self) -> dict:
        def med(m):
            return {"sigma_s": m.sigma_s, "sigma_a": m.sigma_a, "g": m.g, "n": m.n, "thickness_mm": m.thickness_mm}

        return {
            "wavelength_nm": self.wavelength_nm,
            "layers": [med(m) for m in self.layers],
            "blood": {k: v for k, v in med(self.blood).items() if k != "thickness_mm"},
        }


def skin_layers(
    wavelength_nm=638,
    tone="fair",
    *,
    epidermis_mm=0.1,
    dermis_mm=1.5,
    fat_mm=8.0,
    blood_saturation=_VENOUS_S,
) -> SkinLayers:
    """Epidermis, dermis and fat at ``wavelength_nm`` for a skin ``tone``, and venous blood.

    Parameters
    ----------
    wavelength_nm : float
        The laser line, nm (638 or 850 in the paper's experiments).
    tone : str or float
        A name of :data:`SKIN_TONES` or a melanosome fraction.
    epidermis_mm, dermis_mm, fat_mm : float
        Layer thicknesses, mm.
    blood_saturation : float
        The blood's oxygen saturation.

    Returns
    -------
    SkinLayers

    See Also
    --------
    skin_model : with any constant replaced.

    Examples
    --------
    >>> s = skin_layers(638, "fair")
    >>> [round(m.sigma_a, 4) for m in s.layers], round(s.blood.sigma_a, 3)
    ([0.9051, 0.002, 0.0462], 0.892)
    """
    line = _line(wavelength_nm)
    for name, v in (("epidermis_mm", epidermis_mm), ("dermis_mm", dermis_mm), ("fat_mm", fat_mm)):
        if not float(v) > 0:
            raise InputError(f"{name} must be positive, got {v}")
    layers = (
        epidermis_medium(line, tone, epidermis_mm),
        dermis_medium(line, dermis_mm),
        fat_medium(line, fat_mm),
    )
    return SkinLayers(line, layers, blood_medium(line, blood_saturation))


#: The layers of the skin model, top first (the names :func:`skin_model` takes optics for).
LAYER_NAMES = ("epidermis", "dermis", "fat")


def skin_model(
    wavelength_nm=638,
    tone="fair",
    *,
    epidermis_mm=0.1,
    dermis_mm=1.5,
    fat_mm=8.0,
    n=SKIN_N,
    g=SKIN_G,
    optics=None,
    blood_saturation=_VENOUS_S,
    blood_mu_a=None,
    blood_mu_s=None,
) -> SkinLayers:
    """A skin model stated by its user: :func:`skin_layers` with any of its constants replaced.

    Parameters
    ----------
    wavelength_nm : {638, 850}
    tone : str or float
        Skin tone (the epidermis' melanin; ignored for a layer whose ``optics`` are given).
    epidermis_mm, dermis_mm, fat_mm : float
        Layer thicknesses, mm.
    n : float
        Refractive index of every layer (the top face against air; 1 for an index-matched surface).
    g : float
        Henyey-Greenstein anisotropy of every layer and of the blood (``mu_s' = mu_s (1 - g)`` is kept
        for layers whose ``optics`` give it; the published layers keep their ``mu_s'``).
    optics : dict, optional
        ``{layer: (mu_s_prime_per_mm, mu_a_per_mm)}`` for layers of :data:`LAYER_NAMES`: their own
        reduced scattering and absorption instead of the published ones.
    blood_saturation : float
        Oxygen saturation of the veins' blood (the published haemoglobin spectra).
    blood_mu_a, blood_mu_s : float, optional
        The blood's absorption and scattering coefficients, mm^-1, instead of the published ones.

    Returns
    -------
    SkinLayers

    See Also
    --------
    skin_layers : the published model.

    Examples
    --------
    >>> s = skin_model(850, "dark", dermis_mm=5.0, n=1.0, optics={"fat": (2.0, 0.03)})
    >>> [m.thickness_mm for m in s.layers], s.layers[0].n, round(s.layers[2].sigma_s * (1 - s.layers[2].g), 3)
    ([0.1, 5.0, 8.0], 1.0, 2.0)
    """
    base = skin_layers(
        wavelength_nm, tone, epidermis_mm=epidermis_mm, dermis_mm=dermis_mm, fat_mm=fat_mm,
        blood_saturation=blood_saturation,
    )  # fmt: skip
    n, g = float(n), float(g)
    if not 1.0 <= n <= 2.0:
        raise InputError(f"the skin's refractive index must be in [1, 2], got {n}")
    if not -1.0 < g < 1.0:
        raise InputError(f"the anisotropy g must be in (-1, 1), got {g}")
    optics = dict(optics or {})
    unknown = set(optics) - set(LAYER_NAMES)
    if unknown:
        raise InputError(f"unknown skin layer {sorted(unknown)[0]!r}; the layers are {', '.join(LAYER_NAMES)}")
    layers = []
    for name, m in zip(LAYER_NAMES, base.layers):
        if name in optics:
            mu_s_prime, mu_a = (float(v) for v in optics[name])
            if not (mu_s_prime > 0 and mu_a >= 0):
                raise InputError(f"the {name}'s mu_s' must be > 0 and mu_a >= 0, got {mu_s_prime}, {mu_a}")
            layers.append(Medium.from_reduced(mu_s_prime, mu_a, g=g, n=n, thickness_mm=m.thickness_mm))
        elif g == m.g:  # the published layer as it is (the same numbers: the shipped tables' keys)
            layers.append(replace(m, n=n))
        else:
            layers.append(
                Medium.from_reduced(m.sigma_s * (1.0 - m.g), m.sigma_a, g=g, n=n, thickness_mm=m.thickness_mm)
            )
    b = base.blood
    blood = replace(
        b, n=n, g=g,
        sigma_s=b.sigma_s if blood_mu_s is None else float(blood_mu_s),
        sigma_a=b.sigma_a if blood_mu_a is None else float(blood_mu_a),
    )  # fmt: skip
    if not (blood.sigma_s > 0 and blood.sigma_a > 0):
        raise InputError(f"the blood's mu_s and mu_a must be positive, got {blood.sigma_s}, {blood.sigma_a}")
    return SkinLayers(base.wavelength_nm, tuple(layers), blood)
