"""The skin model a depth fit uses, as its user states it: layers, index, anisotropy, blood.

The vein depth fit (:mod:`planeray.skin.depth`) needs the skin's forward model: the layers' thicknesses,
their optics and index, and the blood of the veins.  :func:`stated_skin_model` builds it from what the user
gives (options of ``planeray skin depth``), else from what the capture records (a simulated stack's
``scene``), else from the published layers of the skin scene (:func:`planeray.optical_data_skin.skin_layers`),
and says where each value came from -- nothing is silently assumed.  Its vein tables are traced once on
demand (:func:`tables_to_trace`, :func:`trace_seconds`) and cached.
"""

from __future__ import annotations

from ..errors import InputError
from ..optical_data_skin import LAYER_NAMES, SKIN_G, SKIN_N, SkinLayers, skin_model

__all__ = ["DEFAULT_THICKNESS_MM", "stated_skin_model", "parse_layer_optics", "tables_to_trace", "trace_seconds"]

#: The skin scene's layer thicknesses, mm (used when neither the user nor the capture states them).
DEFAULT_THICKNESS_MM = {"epidermis": 0.1, "dermis": 1.5, "fat": 8.0}


def parse_layer_optics(items) -> dict:
    """``["dermis=2.2,0.003", ...]`` (``LAYER=MU_S_PRIME,MU_A`` in mm^-1) -> ``{layer: (mu_s', mu_a)}``.

    Examples
    --------
    >>> parse_layer_optics(["fat=2.0,0.03"])
    {'fat': (2.0, 0.03)}
    """
    out = {}
    for item in items or ():
        name, sep, values = str(item).partition("=")
        parts = values.split(",")
        try:
            if not sep or len(parts) != 2:
                raise ValueError
            mu_s_prime, mu_a = float(parts[0]), float(parts[1])
        except ValueError:
            raise InputError(
                f"layer optics must read LAYER=MU_S_PRIME,MU_A (mm^-1, e.g. dermis=2.2,0.003), got {item!r}"
            ) from None
        name = name.strip()
        if name not in LAYER_NAMES:
            raise InputError(f"unknown skin layer {name!r} in {item!r}; the layers are {', '.join(LAYER_NAMES)}")
        if not (mu_s_prime > 0 and mu_a >= 0):
            raise InputError(f"{item!r}: mu_s' must be > 0 and mu_a >= 0 (mm^-1)")
        out[name] = (mu_s_prime, mu_a)
    return out


def _recorded(scene: dict, key: str):
    v = scene.get(key) if isinstance(scene, dict) else None
    return None if isinstance(v, bool) or not isinstance(v, (int, float)) else float(v)


def stated_skin_model(
    metadata,
    *,
    tone,
    wavelength_nm: int,
    epidermis_mm=None,
    dermis_mm=None,
    fat_mm=None,
    n=None,
    g=None,
    optics=None,
    blood_saturation=None,
    blood_mu_a=None,
    blood_mu_s=None,
) -> tuple[SkinLayers, dict]:
    """The skin model of a depth fit and where each of its values came from.

    Parameters
    ----------
    metadata : dict
        The stack's metadata (a simulated skin stack records its scene: thicknesses).
    tone, wavelength_nm
        The skin's tone (melanin of the epidermis) and the wavelength (nm).
    epidermis_mm, dermis_mm, fat_mm, n, g : float, optional
        As the user states them; else the capture's record, else the skin scene's.
    optics : dict, optional
        ``{layer: (mu_s', mu_a)}`` (:func:`parse_layer_optics`).
    blood_saturation, blood_mu_a, blood_mu_s : float, optional
        The veins' blood (:func:`planeray.optical_data_skin.skin_model`).

    Returns
    -------
    (SkinLayers, dict)
        The model and ``{value: source}`` (``"option"``, ``"stack metadata"`` or ``"the skin scene's default"``).
    """
    scene = metadata.get("scene") if isinstance(metadata, dict) else None
    sources = {}
    thick = {}
    for name, value in (("epidermis", epidermis_mm), ("dermis", dermis_mm), ("fat", fat_mm)):
        key = f"{name}_mm"
        if value is not None:
            thick[key], sources[key] = float(value), "option"
        elif _recorded(scene, key) is not None:
            thick[key], sources[key] = _recorded(scene, key), "stack metadata"
        else:
            thick[key], sources[key] = DEFAULT_THICKNESS_MM[name], "the skin scene's default"
    sources["n"] = "option" if n is not None else "the skin scene's default"
    sources["g"] = "option" if g is not None else "the skin scene's default"
    sources["layer_optics"] = dict.fromkeys(optics or {}, "option") or "published (Jacques 2013; Bashkatov 2005)"
    blood = {}
    for key, value in (("blood_mu_a", blood_mu_a), ("blood_mu_s", blood_mu_s)):
        if value is not None:
            blood[key] = float(value)
            sources[key] = "option"
    kw = {} if blood_saturation is None else {"blood_saturation": float(blood_saturation)}
    model = skin_model(
        wavelength_nm, tone, **thick, n=SKIN_N if n is None else float(n), g=SKIN_G if g is None else float(g),
        optics=optics, **blood, **kw,
    )  # fmt: skip
    return model, sources


def tables_to_trace(model: SkinLayers, tone, *, mm_per_row: float) -> list:
    """The layer stacks whose vein tables a depth fit of ``model`` would trace (empty: all shipped or cached)."""
    from ..optical_data_skin import skin_layers
    from ..scenes.skin import skin_tables_to_trace

    th = dict(epidermis_mm=model.layers[0].thickness_mm, dermis_mm=model.layers[1].thickness_mm,
              fat_mm=model.layers[2].thickness_mm)  # fmt: skip
    if model == skin_layers(model.wavelength_nm, tone, **th):
        return skin_tables_to_trace(model.wavelength_nm, tone, mm_per_row=mm_per_row, **th)
    return skin_tables_to_trace(mm_per_row=mm_per_row, skin=model)


def trace_seconds(stacks, *, mm_per_row: float) -> float:
    """Estimated seconds to trace the vein tables of ``stacks`` on this machine (a timed pilot run each)."""
    from ..kernels.vein import vein_table_seconds
    from ..scenes.skin import TABLE_PHOTONS

    return float(
        sum(vein_table_seconds(s.layers, s.blood, mm_per_row=mm_per_row, n_photons=TABLE_PHOTONS) for s in stacks)
    )
