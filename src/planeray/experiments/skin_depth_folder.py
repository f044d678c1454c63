"""The folder of ``planeray skin depth`` as a function: each vein's depth and diameter from the delay sweep.

:func:`vein_depths` does the command's whole work -- checks before any work, the skin model
stated (the stack's record, the options), its vein tables traced where not shipped, each vein
fitted, the folder written atomically -- so a notebook produces the same files, bytes and
``planeray.json`` as the command line.  Options are keyword-only; ``progress`` and ``note`` are
as in :mod:`planeray.experiments.workflow`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..errors import InputError, parameter_name
from ..io import atomic_directory, jsonable
from ..io.atomic import MARKER
from ..io.lock import writes_output
from .skin_folders import (
    _load_stack,
    _scale,
    _truth_for,
    _write_csv,
    _write_tiff,
    check_mm_per_row,
    check_tone,
    check_wavelength,
    source_kind,
)
from .workflow import Stages, check_folder_output

__all__ = ["vein_depths", "check_skin_options", "JOINT_ROUNDS"]

#: Rounds of refitting each vein with its neighbours' shadows (skin.depth.fit_veins).
JOINT_ROUNDS = 1


def _recorded(option, name: str, metadata, key: str, parse):
    """An option's value and where it came from: as given, else the stack's scene record; one line if neither."""
    option_name = parameter_name(name)
    if option is not None:
        return parse(option), option_name
    scene = metadata.get("scene") if isinstance(metadata, dict) else None
    value = scene.get(key) if isinstance(scene, dict) else None
    if value is None or isinstance(value, bool):
        raise InputError(f"{option_name}: the stack records no {key}; give {option_name}")
    try:
        return parse(value), "stack metadata"
    except (TypeError, ValueError) as exc:
        raise InputError(f"the stack's recorded {key} {value!r} is not usable ({exc}); give {option_name}") from None


def _stack_camera(metadata):
    """The camera noise model the stack records, else the default one (and which)."""
    from ..camera import CameraModel

    cam = metadata.get("camera") if isinstance(metadata, dict) else None
    if isinstance(cam, dict):
        try:
            return CameraModel(**cam), "stack metadata"
        except (TypeError, ValueError):
            pass
    return CameraModel(), "assumed (planeray's default camera; the stack records none)"


def _truth_depths(stack_path: Path, vein_id) -> dict:
    """``{fitted vein id: (true top depth, true diameter) mm}`` from the ground truth beside a simulated
    stack (each fitted vein matched to the true vein it overlaps most); ``{}`` without truth."""
    from .skin_capture import read_skin_truth, truth_paths

    if not truth_paths(stack_path)["veins"].is_file():
        return {}
    meta, maps = read_skin_truth(stack_path)
    true_id = np.asarray(maps.get("vein_id", np.zeros(0)))
    if true_id.shape != np.shape(vein_id):
        return {}
    spec = {int(v["id"]): (float(v["depth_mm"]), float(v["diameter_mm"])) for v in meta.get("veins", [])}
    out = {}
    for vid in np.unique(vein_id[vein_id > 0]):
        hits = true_id[(vein_id == vid) & (true_id > 0)]
        if hits.size:
            best = int(np.bincount(hits).argmax())
            if best in spec:
                out[int(vid)] = spec[best]
    return out


#: The skin model's options a depth fit may state, with their ranges (closed below, or open) and units.
_SKIN_BOUNDS = {
    "epidermis_mm": ((0.0, 10.0), False),
    "dermis_mm": ((0.0, 20.0), False),
    "fat_mm": ((0.0, 100.0), False),
    "n": ((1.0, 2.0), True),
    "g": ((-1.0, 1.0), False),
    "blood_saturation": ((0.0, 1.0), True),
    "blood_mu_a": ((0.0, 100.0), False),
    "blood_mu_s": ((0.0, 1000.0), False),
}


def check_skin_options(*, tone=None, wavelength_nm=None, mm_per_row=None, layer_optics=None, **stated):
    """The options of :func:`vein_depths` that need no file, checked; returns the parsed ``layer_optics``."""
    from ..skin.model import parse_layer_optics

    if tone is not None:
        check_tone(tone)
    if wavelength_nm is not None:
        check_wavelength(wavelength_nm)
    if mm_per_row is not None:
        check_mm_per_row(mm_per_row)
    for name, ((lo, hi), closed) in _SKIN_BOUNDS.items():
        value = stated.get(name)
        if value is None:
            continue
        inside = math.isfinite(value) and (lo <= value if closed else lo < value) and value <= hi
        if not inside or (name == "g" and value >= hi):
            raise InputError(
                f"{parameter_name(name)} must be in {'[' if closed else '('}{lo:g}, {hi:g}], got {value:g}"
            )
    try:
        return parse_layer_optics(layer_optics)
    except InputError as exc:
        raise InputError(f"{parameter_name('layer_optics')}: {exc}") from None


def _trace_tables(st, skin, tone, wl, mpr, stages: Stages) -> None:
    """The skin model's vein tables, traced first (noted, with a time estimate) where neither shipped nor cached."""
    from ..skin.model import tables_to_trace, trace_seconds

    to_trace = tables_to_trace(skin, tone, mm_per_row=mpr)
    if not to_trace:
        return
    from ..mc.cache import cache_dir
    from ..scenes.skin import TABLE_PHOTONS
    from ..skin.depth import vein_model

    stages.stage("estimating the time to trace the skin model's vein tables")
    seconds = trace_seconds(to_trace, mm_per_row=mpr)
    stages.note(
        f"the vein tables of this skin model ({len(to_trace)}) are neither shipped nor cached: tracing them "
        f"by Monte Carlo first ({len(to_trace) * TABLE_PHOTONS:,} photons, about {seconds / 60:.0f} minutes on "
        f"this machine, measured on a pilot run; once: cached in {cache_dir()})"
    )
    advance = stages.stage("tracing the vein tables (photons)", len(to_trace) * TABLE_PHOTONS)
    vein_model(st.bands(), st.geometry, tone=tone, wavelength_nm=wl, mm_per_row=mpr, skin=skin, progress=advance)


def _vein_ids(truth) -> np.ndarray:
    """The veins to fit: the mask's (the truth's, less those under hair or off the skin); refused if none."""
    if truth is None:
        raise InputError(f"{parameter_name('mask')}: give a vein mask (there is no ground truth beside the stack)")
    vein_id = np.asarray(truth["vein_id"])
    if truth.get("exclude") is not None:  # the truth's veins under hair or off the skin: not fitted
        vein_id = np.where(np.asarray(truth["exclude"], bool), 0, vein_id)
    if not np.unique(vein_id[vein_id > 0]).size:
        raise InputError(f"{parameter_name('mask')}: the vein mask marks no vein")
    return vein_id


def _write_depth_folder(out_dir, result, fits, vein_id, true_depths, title, overwrite) -> None:
    from PIL import Image

    from ..figures.skin import depth_fit_figure

    depth_map = np.full(vein_id.shape, np.nan, np.float32)
    flag_map = np.full(vein_id.shape, 255, np.uint8)
    for f in fits:
        if f.resolved:
            depth_map[vein_id == f.id] = f.depth_mm
        flag_map[vein_id == f.id] = f.flags
    with atomic_directory(out_dir, overwrite=overwrite, kind="skin depth") as tmp:
        Image.fromarray(vein_id.astype(np.uint16)).save(tmp / "vein_ids.png", format="PNG")
        _write_tiff(tmp / "depth_mm.tif", depth_map)
        _write_tiff(tmp / "flags.tif", flag_map, np.uint8)
        _write_csv(tmp / "veins.csv", result["veins"])
        depth_fit_figure(
            [{**f.to_json(), "curves": f.curves} for f in fits],
            truth=true_depths or None,
            title=title,
            out=tmp / "depth_fit.png",
        )
        (tmp / MARKER).write_text(json.dumps(jsonable(result), indent=1))


#: How the depth fit judges its own fit (its ``planeray.json``).
_DEPTH_GOODNESS = (
    "each vein's chi-square against the camera's noise model with the model's error (its contrast scaled "
    "by 1 + s, s fitted with a prior of 0.15; 2 % of each sample's laser light), and the images' "
    "backgrounds against the skin model's kernel (3 %): a fit less probable than p = 0.001 is flagged "
    "'model does not fit' and its standard errors are scaled by sqrt(chi2 / dof); a depth or diameter at "
    "the tables' edge is flagged and not reported"
)


@writes_output("out_dir")
def vein_depths(
    stack,
    out_dir,
    *,
    mask=None,
    tone=None,
    wavelength_nm: int | None = None,
    mm_per_row: float | None = None,
    epidermis_mm: float | None = None,
    dermis_mm: float | None = None,
    fat_mm: float | None = None,
    n: float | None = None,
    g: float | None = None,
    layer_optics=None,
    blood_saturation: float | None = None,
    blood_mu_a: float | None = None,
    blood_mu_s: float | None = None,
    overwrite: bool = False,
    progress=None,
    note=None,
) -> dict:
    """Depth (of the vessel's top and axis) and diameter of each vein, with standard errors, from the delay sweep.

    Writes the folder of ``planeray skin depth``: ``vein_ids.png`` (uint16 ids of the veins fitted),
    ``depth_mm.tif`` (float32, each resolved vein's top depth, NaN elsewhere), ``flags.tif`` (uint8
    flag bits per vein, 255 off the veins), ``veins.csv``, ``depth_fit.png`` and ``planeray.json``.
    Veins the delay images cannot resolve are reported with the reason, never with a number; every
    fit says whether the skin model fits the images.

    Parameters
    ----------
    stack : str or os.PathLike
        Stack (Zarr or import folder) with its delay sweep.
    out_dir : str or os.PathLike
        Folder to write.
    mask : str or os.PathLike, optional
        Vein mask (0 skin, nonzero vein; several values: vein ids, else one vein per connected
        region); default: the ground truth ``planeray skin simulate`` wrote beside the stack.
    tone : str or float, optional
        Skin tone (``very_fair`` ... ``dark``) or melanosome fraction 0-0.5; default: the stack's record.
    wavelength_nm : int, optional
        638 or 850; default: the stack's record.
    mm_per_row : float, optional
        Size of a projector row on the skin, mm, in (0, 10]; default: the stack's record; neither: refused.
    epidermis_mm, dermis_mm, fat_mm : float, optional
        Layer thicknesses, mm (default: the stack's record, else 0.1, 1.5, 8).
    n, g : float, optional
        Refractive index (default 1.4) and Henyey-Greenstein anisotropy (default 0.9) of the layers.
    layer_optics : list of str, optional
        ``LAYER=MU_S_PRIME,MU_A`` (1/mm): a layer's own optics instead of the published ones.
    blood_saturation, blood_mu_a, blood_mu_s : float, optional
        The veins' blood: oxygen saturation (0-1, default 0.7), absorption and scattering (1/mm).
    overwrite : bool
        Replace an output folder planeray wrote.
    progress, note : callable, optional
        As in :mod:`planeray.experiments.workflow`.

    Returns
    -------
    dict
        The record written to ``planeray.json`` (its ``veins``: one entry per vein).
    """
    from ..skin.depth import fit_veins
    from ..skin.model import stated_skin_model

    stages = Stages(progress, note)
    stated = dict(epidermis_mm=epidermis_mm, dermis_mm=dermis_mm, fat_mm=fat_mm, n=n, g=g,
                  blood_saturation=blood_saturation, blood_mu_a=blood_mu_a, blood_mu_s=blood_mu_s)  # fmt: skip
    optics = check_skin_options(
        tone=tone, wavelength_nm=wavelength_nm, mm_per_row=mm_per_row, layer_optics=layer_optics, **stated
    )
    out_dir = check_folder_output(
        out_dir, [(parameter_name("stack"), stack), (parameter_name("mask"), mask)], overwrite=overwrite,
        kind="skin depth",
    )  # fmt: skip
    if source_kind(stack, "stack") != "stack":
        raise InputError(f"a transport store has no delay sweep: give the stack ({parameter_name('stack')})", stack)
    st = _load_stack(stack)
    tone_value, tone_source = _recorded(tone, "tone", st.metadata, "tone", lambda v: check_tone(str(v)))
    wl, wl_source = _recorded(
        wavelength_nm, "wavelength_nm", st.metadata, "wavelength_nm", lambda v: check_wavelength(int(v))
    )
    mpr, mpr_source = _scale(mm_per_row, ("stack metadata", st.metadata))
    if mpr_source.startswith("assumed"):
        raise InputError(
            f"{stack} does not record the size of a projector row on the skin: give {parameter_name('mm_per_row')}, "
            'or add "mm_per_row" to the capture\'s acquisition.json'
        )
    camera, camera_source = _stack_camera(st.metadata)
    skin, skin_sources = stated_skin_model(st.metadata, tone=tone_value, wavelength_nm=wl, optics=optics, **stated)
    _trace_tables(st, skin, tone_value, wl, mpr, stages)
    truth = _truth_for(st.shape, Path(stack), mask)
    vein_id = _vein_ids(truth)
    n_veins = int(np.unique(vein_id[vein_id > 0]).size)
    true_depths = _truth_depths(Path(stack), vein_id)
    rounds = 1 + (JOINT_ROUNDS if n_veins > 1 else 0)  # each vein alone, then with the others' shadows
    advance = stages.stage(f"fitting {n_veins} vein(s)", n_veins * rounds)
    try:
        fits, _, use = fit_veins(
            st.images, st.bands(), st.geometry, vein_id, camera=camera, excluded=st.excluded, tone=tone_value,
            wavelength_nm=wl, mm_per_row=mpr, skin=skin, joint_rounds=JOINT_ROUNDS, progress=lambda vid: advance(),
        )  # fmt: skip
    except InputError as exc:
        raise InputError(f"{stack}: {exc}") from None
    veins_json = []
    for f in fits:
        j = f.to_json()
        if true_depths:
            j["true_depth_mm"], j["true_diameter_mm"] = true_depths.get(f.id, (None, None))
        veins_json.append(j)
    result = {
        "format": "planeray-skin-depth",
        "format_version": 1,
        "stack": str(stack),
        "depth_is": "depth_mm: of the vessel's top (its wall nearest the surface); axis_depth_mm = depth_mm + "
        "diameter_mm / 2; mm below the skin's surface",
        "tone": tone_value,
        "tone_source": tone_source,
        "wavelength_nm": wl,
        "wavelength_source": wl_source,
        "mm_per_row": mpr,
        "mm_per_row_source": mpr_source,
        "skin_model": skin.to_json(),
        "skin_model_sources": skin_sources,
        "camera_source": camera_source,
        "goodness_of_fit": _DEPTH_GOODNESS,
        "mask": truth["source"],
        "images_used": [int(i) for i in np.nonzero(use)[0]],
        "ambient": fits[0].curves.get("ambient") if fits else None,
        "veins": veins_json,
    }
    title = f"Vein depth: {Path(stack).name} ({tone_value}, {wl} nm)"
    _write_depth_folder(out_dir, result, fits, vein_id, true_depths, title, overwrite)
    return result
