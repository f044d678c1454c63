"""The skin scene: optical constants, the interface other modules rely on, and its ground truth."""

from __future__ import annotations

import json

import numpy as np
import pytest

from planeray.errors import InputError
from planeray.optical_data_skin import SKIN_TONES, blood_mu_a, skin_layers, tone_fraction
from planeray.scenes import make_scene
from planeray.scenes.skin import skin_veins
from planeray.timing import Band

LPS = 54_000.0


# ----------------------------------------------------------------------------- optical constants
def test_optical_constants_match_issue():
    """The numbers issue 13 quotes (Jacques 2013 formulas, mm^-1) at 638 and 850 nm."""
    issue = {
        638: dict(epi=(0.905, 31.4), dermis=(0.0021, 22.5), blood=(0.892, 7.84)),
        850: dict(epi=(0.351, 23.5), dermis=(0.0038, 12.6), blood=(0.512, 5.88)),
    }
    for w, ref in issue.items():
        s = skin_layers(w, 0.03)  # 3 % melanosomes: the issue's epidermis
        epi, dermis, fat = s.layers
        assert epi.sigma_a == pytest.approx(ref["epi"][0], rel=0.01)
        assert epi.sigma_s == pytest.approx(ref["epi"][1], rel=1e-6)
        assert dermis.sigma_a == pytest.approx(ref["dermis"][0], rel=0.07)
        assert dermis.sigma_s == pytest.approx(ref["dermis"][1], rel=1e-6)
        assert s.blood.sigma_a == pytest.approx(ref["blood"][0], rel=1e-9)
        assert s.blood.sigma_s == pytest.approx(ref["blood"][1], rel=1e-9)
        for m in (*s.layers, s.blood):
            assert m.g == 0.9 and 1.37 <= m.n <= 1.4
        # fat: mu_s' of Bashkatov (2.7 mm^-1 at 600 nm) falling with wavelength
        assert 2.0 < fat.sigma_s_prime < 2.7
    # blood absorbs more when deoxygenated at 638 nm, less at 850 nm (the isosbestic point is ~800 nm)
    assert blood_mu_a(638, 0.0) > blood_mu_a(638, 1.0)
    assert blood_mu_a(850, 0.0) < blood_mu_a(850, 1.0)
    assert [tone_fraction(t) for t in SKIN_TONES] == sorted(SKIN_TONES.values())
    with pytest.raises(InputError, match="tabulated"):
        skin_layers(532)
    with pytest.raises(InputError, match="tone"):
        skin_layers(638, "green")


# ----------------------------------------------------------------------------- the interface
@pytest.fixture(scope="module")
def scene():
    return make_scene("skin", (64, 64), projector_rows=720, seed=2, hair=True)


def test_skin_scene_interface(scene):
    H, W = scene.shape
    m = scene.maps
    assert m["vein_mask"].dtype == bool and m["vein_mask"].shape == (H, W)
    assert m["vein_id"].dtype == np.int32
    for k in ("vein_depth_mm", "vein_diameter_mm", "vein_axis_depth_mm"):
        assert m[k].dtype == np.float32
        assert np.all(np.isnan(m[k][~m["vein_mask"]])) and np.all(np.isfinite(m[k][m["vein_mask"]]))
    assert np.array_equal(m["vein_mask"], m["vein_id"] > 0)
    assert m["hair"].dtype == bool and m["hair"].any()
    assert np.all(scene.labels == 2)  # skin everywhere: subsurface
    params = json.loads(json.dumps(scene.params))
    ids = {v["id"] for v in params["veins"]}
    assert set(np.unique(m["vein_id"])) - {0} <= ids
    for v in params["veins"]:
        assert 1 <= v["depth_mm"] <= 5 and 1 <= v["diameter_mm"] <= 4
        assert v["axis_depth_mm"] == pytest.approx(v["depth_mm"] + v["diameter_mm"] / 2)
        sel = m["vein_id"] == v["id"]
        assert np.all(m["vein_depth_mm"][sel] == np.float32(v["depth_mm"]))
    assert params["wavelength_nm"] == 638 and params["tone"] == "fair"


def test_explicit_vein_ground_truth():
    """A straight vein parallel to the rows: its mask is exactly the rows within its radius."""
    H = W = 48
    P, mm = 240, 0.3  # 72 mm field, 1.5 mm per camera row
    x_axis = 36.0  # mm from the top edge
    vein = dict(depth_mm=2.0, diameter_mm=4.0, points_mm=[[x_axis, -10.0], [x_axis, 100.0]])
    s = make_scene("skin", (H, W), projector_rows=P, seed=0, veins=[vein])
    x_pix = (np.arange(H) + 0.5) * P * mm / H
    expect = np.abs(x_pix - x_axis) <= 2.0
    assert np.array_equal(s.maps["vein_mask"], np.broadcast_to(expect[:, None], (H, W)))
    (gt,) = skin_veins(s)
    assert gt.id == 1 and gt.depth_mm == 2.0 and gt.axis_depth_mm == 4.0
    assert np.array_equal(gt.mask, s.maps["vein_mask"])
    # The vein darkens the short-range indirect image over it (paper delays, 400-600 us).
    none = make_scene("skin", (H, W), projector_rows=P, seed=0, veins=[])
    img, ref = (x.transport.render(Band(500.0, 200.0, LPS)) for x in (s, none))
    c = 1.0 - img[expect].mean() / ref[expect].mean()
    assert 0.05 < c < 0.9
    # ... and far less the flood-lit (ambient) reflectance, where it is faint but present
    ca = 1.0 - s.ambient_albedo[expect].mean() / none.ambient_albedo[expect].mean()
    assert 0.002 < ca < c / 2


def test_bad_veins_are_refused():
    with pytest.raises(InputError, match="depth_mm"):
        make_scene("skin", (16, 16), veins=[dict(depth_mm=9.0, diameter_mm=2.0, points_mm=[[0, 0], [1, 1]])])
    with pytest.raises(InputError, match="points_mm"):
        make_scene("skin", (16, 16), veins=[dict(depth_mm=2.0, diameter_mm=2.0, points_mm=[[0, 0]])])
    with pytest.raises(InputError, match="skin scene"):
        skin_veins(make_scene("diffuse_plane", (16, 16)))
