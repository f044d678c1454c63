"""Built-in scenes: determinism, shapes, physics sanity and each scene's delay-profile signature."""

from __future__ import annotations

import json

import numpy as np
import pytest

from planeray.medium import Medium
from planeray.scenes import EFFECTS, footprint_kernel, list_scenes, make_scene
from planeray.scenes.wax import wax_kernel
from planeray.timing import Band

LPS = 54_000.0
SCENES = sorted(list_scenes())
NEW_SCENES = ["wax", "corner", "mirror_ball", "disco_ball"]
SHAPE = (64, 80)


@pytest.fixture(scope="module")
def built():
    """Each scene once at 96x96 (seed 0), shared by the physics tests."""
    return {name: make_scene(name, (96, 96), seed=0) for name in NEW_SCENES}


def _disk_outside(scene, margin_px=1.0):
    """Pixels whose centre lies clearly outside a ball scene's image disk."""
    H, W = scene.shape
    R = scene.params["radius"] * H
    yy, xx = np.mgrid[:H, :W] + 0.5
    return np.hypot(yy - 0.5 * H, xx - 0.5 * W) > R + margin_px


def _sparse_sum(transport):
    out = np.zeros(transport.shape)
    sp = transport.sparse
    np.add.at(out, (sp.row, sp.col), sp.value)
    return out


# ----------------------------------------------------------------------------- generic
def test_new_scenes_are_registered():
    for name in NEW_SCENES:
        assert name in SCENES
        assert isinstance(list_scenes()[name], str) and list_scenes()[name]


@pytest.mark.parametrize("name", SCENES)
def test_deterministic_and_seeded(name):
    a = make_scene(name, SHAPE, seed=3)
    b = make_scene(name, SHAPE, seed=3)
    c = make_scene(name, SHAPE, seed=4)
    assert a.transport.dense.tobytes() == b.transport.dense.tobytes()
    for field in ("row", "col", "offset", "value"):
        assert getattr(a.transport.sparse, field).tobytes() == getattr(b.transport.sparse, field).tobytes()
    assert a.direct.tobytes() == b.direct.tobytes()
    assert a.labels.tobytes() == b.labels.tobytes()
    assert a.params == b.params
    assert not np.array_equal(a.ambient_albedo, c.ambient_albedo), "textures must depend on the seed"


@pytest.mark.parametrize("name", SCENES)
def test_shapes_dtypes_and_values(name):
    s = make_scene(name, SHAPE, seed=0)
    T = s.transport
    H, W = SHAPE
    assert T.dense.shape[:2] == (H, W) and T.dense.dtype == np.float32
    assert T.dense.shape[2] == T.offsets_rows.size
    for img in (s.direct, s.ambient_albedo):
        assert img.shape == (H, W) and img.dtype == np.float32
        assert np.all(np.isfinite(img)) and img.min() >= 0
    assert s.labels.shape == (H, W) and s.labels.dtype == np.uint8
    assert set(np.unique(s.labels)) <= set(EFFECTS)
    assert np.all(np.isfinite(T.dense)) and T.dense.min() >= 0
    assert np.all(np.isfinite(T.sparse.value)) and (len(T.sparse) == 0 or T.sparse.value.min() >= 0)
    if len(T.sparse):  # sparse entries live outside the dense band
        assert np.all((T.sparse.offset < T.offsets_rows[0]) | (T.sparse.offset > T.offsets_rows[-1]))
    json.dumps(s.params)
    assert s.params["name"] == name


@pytest.mark.parametrize("name", NEW_SCENES)
def test_epipolar_image_is_direct_where_no_near_indirect(built, name):
    s = built[name]
    plain = s.labels == 1
    assert plain.sum() > 0.05 * plain.size
    err = np.abs(s.transport.epipolar_image() - s.direct)[plain]
    assert err.mean() < 1e-3
    assert err.max() < 0.03


@pytest.mark.parametrize("name", NEW_SCENES)
def test_projector_rows_720(name):
    s = make_scene(name, (128, 128), projector_rows=720, seed=1)
    T = s.transport
    assert T.geometry.projector_rows == 720 and T.shape == (128, 128)
    assert s.params["projector_rows"] == 720
    # A pixel lit only directly: its peak is the camera row's footprint, ~5.6 projector rows.
    near = np.abs(T.offsets_rows) <= 10
    only_direct = (s.labels == 1) & np.isclose(T.dense[:, :, near].sum(axis=2), s.direct, atol=1e-6)
    t, c = np.argwhere(only_direct & (s.direct > 0.05))[0]
    prof = T.dense[t, c]
    support = T.offsets_rows[prof > 1e-6 * prof.max()]
    assert 5 <= support.size <= 8 and support.min() >= -4 and support.max() <= 4
    np.testing.assert_allclose(
        prof[near] / s.direct[t, c], footprint_kernel(T.offsets_rows, 720 / 128)[near], atol=1e-5
    )
    img = T.render(Band(0.0, 600.0, LPS))
    assert img.shape == (128, 128) and np.all(np.isfinite(img))


# ----------------------------------------------------------------------------- wax
def test_wax_glow_dominates_regular_epipolar_image(built):
    s = built["wax"]
    wax = s.labels == 2
    img = s.transport.render(Band(0.0, 600.0, LPS))  # 32.4-row band
    epi = s.transport.epipolar_image()  # the 1-row epipolar image
    assert img[wax].mean() > 4.0 * s.direct[wax].mean()  # 4.4x with the defaults
    assert img[wax].mean() > 2.0 * epi[wax].mean()
    # Background: direct light only.
    np.testing.assert_allclose(img[~wax], s.direct[~wax], atol=1e-6)
    # Subsurface light per pixel never exceeds the medium's total diffuse reflectance.
    glow = s.transport.full_image() - s.direct
    assert glow[wax].max() <= 1.1 * s.params["subsurface_total_reflectance"]


@pytest.mark.parametrize("model", ["mc", "dipole"])
def test_wax_kernel_is_broad(model):
    medium = Medium.from_reduced(0.3, 0.003, g=0.8, n=1.4)  # the scene's defaults
    u = np.arange(-16, 17)  # the 600 us band
    k, total = wax_kernel(medium, u, 1.0, mm_per_row=0.3, model=model)
    assert k[np.abs(u) > 3].sum() > 0.3 * k.sum()
    assert np.argmax(k) == 16 and np.all(np.diff(k[16:]) < 0)
    assert 0.3 < total < 0.9 and k.sum() < total


def test_wax_monte_carlo_kernel_agrees_with_dipole_in_diffusion_regime():
    # Same sigma_s' and eta: the dipole is the diffusion limit of the MC medium, so the
    # skirt (several transport mean free paths out) has the same decay; near the line
    # MC keeps the single-scattering peak the dipole smooths away.
    medium = Medium.from_reduced(0.3, 0.003, g=0.8, n=1.4)
    u = np.arange(-128, 129)
    k_mc, r_mc = wax_kernel(medium, u, 1.0, mm_per_row=0.3, model="mc")
    k_dp, r_dp = wax_kernel(medium, u, 1.0, mm_per_row=0.3, model="dipole")
    assert abs(r_mc / r_dp - 1.0) < 0.1
    far = (np.abs(u) >= 40) & (np.abs(u) <= 100)  # 12-30 mm: 4-9 transport mfp
    slope_mc = np.polyfit(np.abs(u[far]), np.log(k_mc[far]), 1)[0]
    slope_dp = np.polyfit(np.abs(u[far]), np.log(k_dp[far]), 1)[0]
    assert abs(slope_mc / slope_dp - 1.0) < 0.1
    assert k_mc[128] > 1.2 * k_dp[128]


def test_wax_light_must_enter_the_wax(built):
    s = built["wax"]
    T, wax = s.transport, s.labels == 2
    t, c = np.argwhere(wax)[0]  # topmost wax pixel
    prof = T.dense[t, c]
    assert prof[T.offsets_rows < -3].sum() < 1e-3 * prof[T.offsets_rows > 3].sum()


# ----------------------------------------------------------------------------- corner
def test_corner_profile_is_one_sided_and_steep(built):
    s = built["corner"]
    T, H = s.transport, s.shape[0]
    crease = s.params["crease_row"]
    indirect = T.dense - s.direct[:, :, None] * footprint_kernel(T.offsets_rows, 1.0)[None, None, :]
    assert indirect.min() > -1e-6
    u = T.offsets_rows
    above, below = np.arange(H) < crease, np.arange(H) >= crease
    assert np.abs(indirect[above][:, :, u < 0]).max() < 1e-7  # wall: light only from below
    assert np.abs(indirect[below][:, :, u > 0]).max() < 1e-7  # floor: light only from above
    sp = T.sparse
    assert np.all(np.where(sp.row < crease, sp.offset > 0, sp.offset < 0))
    # Steep: next to the crease the first row of the other face gives most of the light.
    prof = indirect[crease - 1].mean(axis=0)
    assert prof[u == 1].sum() > 0.4 * prof.sum()
    assert np.argmax(prof) == np.flatnonzero(u == 1)[0]
    assert s.labels[crease - 1].min() == 3 and s.labels[crease].min() == 3


def test_corner_energy_bounded_by_form_factor(built):
    s = built["corner"]
    T, crease = s.transport, s.params["crease_row"]
    indirect = T.full_image() - s.direct
    rho = s.direct
    for face, other in ((slice(0, crease), slice(crease, None)), (slice(crease, None), slice(0, crease))):
        bound = rho[face] * rho[other].max() / 2.0  # total 2D form factor of the other face: 1/2
        assert np.all(indirect[face] <= bound + 1e-5)


@pytest.mark.parametrize("projector_rows", [None, 720])
def test_corner_matches_closed_form_total(projector_rows):
    """Uniform faces: a wall row gets rho_A rho_B 1/2 (1 - a / sqrt(a^2 + B^2)) in total."""
    H = 64 if projector_rows is None else 128
    s = make_scene("corner", (H, 48), projector_rows=projector_rows, seed=0, textured=False)
    g, p = s.geometry, s.params
    rpc, crease = g.rows_per_camera_row, p["crease_row"]
    x_c = crease * rpc - 0.5
    B = (g.projector_rows - 0.5 - x_c) * p["mm_per_row_b"]
    n = 64
    y = (np.arange(crease)[:, None] + (np.arange(n) + 0.5) / n) * rpc - 0.5
    a = (x_c - y) * p["mm_per_row_a"]
    expected = (0.5 * (1.0 - a / np.sqrt(a * a + B * B))).mean(axis=1) * 0.65 * 0.55
    got = (s.transport.full_image() - s.direct)[:crease]
    np.testing.assert_allclose(got, np.broadcast_to(expected[:, None], got.shape), rtol=2e-3, atol=1e-5)
    # Scale-free but steepest next to the crease: the total grows toward it.
    assert np.all(np.diff(expected) > 0)


def test_corner_second_bounce_is_small_and_positive():
    one = make_scene("corner", (64, 64), seed=0)
    two = make_scene("corner", (64, 64), seed=0, bounces=2)
    extra = two.transport.dense - one.transport.dense
    assert extra.min() > -1e-6 and extra.sum() > 0
    rho = one.direct
    assert np.all(extra.sum(axis=2) <= rho * rho.max() ** 2 / 4 + 1e-5)
    with pytest.raises(ValueError):
        make_scene("corner", (64, 64), bounces=3)


# ----------------------------------------------------------------------------- mirror ball
def test_mirror_ball_page_profile_is_bimodal(built):
    s = built["mirror_ball"]
    T, (H, W) = s.transport, s.shape
    R = s.params["radius"] * H
    u = T.offsets_rows
    for row in (int(0.5 * H - 1.4 * R), int(0.5 * H + 1.4 * R)):  # above and below the ball
        prof = T.dense[row, W // 2]
        assert np.argmax(prof) == np.flatnonzero(u == 0)[0]  # diffuse peak at u = 0
        side = u > 1 if row < H / 2 else u < -1  # above: light from lower rows (u > 0)
        k2 = np.flatnonzero(side)[np.argmax(prof[side])]
        assert prof[k2] > 0.01 * prof.max() and abs(u[k2]) >= 3
        between = prof[min(k2, np.flatnonzero(u == 0)[0]) + 1 : max(k2, np.flatnonzero(u == 0)[0])]
        assert between.size and between.min() < 0.1 * prof[k2]  # two separated peaks
    assert s.labels[int(0.5 * H - 1.4 * R), W // 2] == 4


def test_mirror_ball_energy_and_splat_agrees_with_gather():
    s = make_scene("mirror_ball", (64, 64), seed=0)
    H = s.shape[0]
    R = s.params["radius"] * H
    page = _disk_outside(s)
    spec = s.transport.full_image() - s.direct
    albedo = s.ambient_albedo
    # Outer ring rho > R / sqrt(2) reflects toward the page: at most 0.9 of its beam lands.
    assert (spec[page] / albedo[page]).sum() <= 0.9 * np.pi * R**2 / 2
    assert (spec[page] / albedo[page]).sum() > 0.1 * np.pi * R**2 / 2
    # A convex mirror spreads the beam thinly: a few percent of the direct light.
    assert (spec[page] / albedo[page]).max() < 0.06
    # Ball pixels see the page at the mirror's reflectance (and only where r_z < 0).
    ball = s.labels == 4
    ball &= ~_disk_outside(s, margin_px=-1.0)
    assert spec[ball].max() <= 0.9 * albedo.max() + 1e-5
    # Monte Carlo forward splat and exact gather give the same ring brightness.
    splat = make_scene("mirror_ball", (64, 64), seed=0, n_splat=16)
    spec2 = splat.transport.full_image() - splat.direct
    yy, xx = np.mgrid[:H, :H] + 0.5
    ring = (np.hypot(yy - H / 2, xx - H / 2) > 1.3 * R) & (np.hypot(yy - H / 2, xx - H / 2) < 1.8 * R)
    np.testing.assert_allclose((spec2[ring] / albedo[ring]).mean(), (spec[ring] / albedo[ring]).mean(), rtol=0.1)


# ----------------------------------------------------------------------------- disco ball
def test_disco_ball_spots_move_with_delay(built):
    s = built["disco_ball"]
    T, (H, W) = s.transport, s.shape
    wall = _disk_outside(s)
    yy = np.mgrid[:H, :W][0] + 0.5

    def spots(delay):
        img = T.render(Band(delay, 600.0, LPS)) * wall  # non-epipolar: spots only
        return img

    up, down = spots(+400.0), spots(-400.0)
    assert up.sum() > 1.0 and down.sum() > 1.0
    # Positive delay: light from lower rows -> spots thrown upward, above their facets.
    c_up, c_down = (up * yy).sum() / up.sum(), (down * yy).sum() / down.sum()
    assert c_down - c_up > 0.25 * H
    # The set of lit spot pixels changes as the delay grows.
    a, b = spots(300.0) > 0.05, spots(600.0) > 0.05
    assert a.sum() and b.sum()
    assert (a & b).sum() < 0.5 * (a | b).sum()
    # Spots are bright (a facet's full flux) and labelled as specular.
    assert up.max() > 0.3
    assert np.all(s.labels[up > 0.1] == 4)


def test_disco_ball_energy_conservation(built):
    s = built["disco_ball"]
    H = s.shape[0]
    R = s.params["radius"] * H
    wall = _disk_outside(s)
    spec = s.transport.full_image() - s.direct
    albedo = s.ambient_albedo
    assert (spec[wall] / albedo[wall]).sum() <= s.params["mirror_reflectance"] * np.pi * R**2
    ball = ~_disk_outside(s, margin_px=-1.0)
    assert spec[ball].max() <= s.params["mirror_reflectance"] * albedo[wall].max() + 1e-5
    assert np.all(s.direct[ball] < 0.1)  # the ball itself is dark (mirror facets, grout)
