"""planeray.medium.Medium: validation, derived values, plain-data round trips, and its use by the models."""

import dataclasses
import doctest
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import planeray
import planeray.medium
from planeray.errors import InputError
from planeray.medium import Medium, as_medium

# ----------------------------------------------------------------------------- the value


@pytest.mark.parametrize(
    ("field", "kwargs"),
    [
        ("sigma_s", dict(sigma_s=-0.1)),
        ("sigma_s", dict(sigma_s=math.inf)),
        ("sigma_s", dict(sigma_s=math.nan)),
        ("sigma_s", dict(sigma_s="thick")),
        ("sigma_a", dict(sigma_a=-1e-9)),
        ("sigma_a", dict(sigma_a=math.nan)),
        ("sigma_a", dict(sigma_a=None)),
        ("g", dict(g=1.0)),
        ("g", dict(g=-1.0)),
        ("g", dict(g=1.5)),
        ("g", dict(g=math.nan)),
        ("n", dict(n=0.0)),
        ("n", dict(n=-1.4)),
        ("n", dict(n=math.inf)),
        ("thickness_mm", dict(thickness_mm=0.0)),
        ("thickness_mm", dict(thickness_mm=-2.0)),
        ("thickness_mm", dict(thickness_mm=math.nan)),
        ("sigma_s + sigma_a", dict(sigma_s=0.0, sigma_a=0.0)),
    ],
)
def test_bad_fields_raise_input_error_naming_them(field, kwargs):
    base = dict(sigma_s=1.0, sigma_a=0.01, g=0.9)
    with pytest.raises(InputError, match=field.replace("+", r"\+")):
        Medium(**{**base, **kwargs})
    with pytest.raises(ValueError):  # InputError is a ValueError: old callers' except clauses still work
        Medium(**{**base, **kwargs})


def test_g_message_is_the_one_the_cli_prints():
    with pytest.raises(InputError, match=r"g must lie in \(-1, 1\), got 1.5"):
        Medium(1.0, 0.0, 1.5)


def test_defaults_types_and_derived_values():
    m = Medium(sigma_s=2, sigma_a=0, g=0)  # ints become floats (they go into JSON cache keys)
    assert (m.n, m.thickness_mm, m.semi_infinite) == (1.0, math.inf, True)
    assert all(type(getattr(m, f.name)) is float for f in dataclasses.fields(m))
    m = Medium(sigma_s=1.0, sigma_a=0.01, g=0.9, n=1.4, thickness_mm=np.float64(3.0))
    assert m.sigma_s_prime == 1.0 * (1.0 - 0.9)
    assert m.sigma_s_prime == pytest.approx(0.1)
    assert m.sigma_t == 1.01 and m.albedo == 1.0 / 1.01
    assert m.transport_mfp_mm == pytest.approx(1.0 / 0.11)
    assert not m.semi_infinite and type(m.thickness_mm) is float


def test_from_reduced_is_the_similarity_relation():
    m = Medium.from_reduced(0.3, 0.003, g=0.8, n=1.4)
    assert m.sigma_s == 0.3 / (1.0 - 0.8) and m.sigma_s_prime == 0.3
    assert (m.sigma_a, m.g, m.n, m.thickness_mm) == (0.003, 0.8, 1.4, math.inf)
    assert Medium.from_reduced(0.5, 0.1, g=0.0) == Medium(0.5, 0.1, 0.0)
    assert Medium.from_reduced(1.0, 0.1, g=0.5, thickness_mm=2.0).thickness_mm == 2.0
    with pytest.raises(InputError, match="g"):
        Medium.from_reduced(0.3, 0.003, g=1.0)
    with pytest.raises(InputError, match="sigma_s_prime"):
        Medium.from_reduced(-0.3, 0.003, g=0.5)


def test_frozen_hashable_and_replace():
    m = Medium(1.0, 0.1, 0.5)
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.g = 0.1
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.sigma_s = 2.0
    assert m == Medium(1.0, 0.1, 0.5) and len({m, Medium(1.0, 0.1, 0.5)}) == 1
    r = m.replace(g=0.0, n=1.33)
    assert r == Medium(1.0, 0.1, 0.0, n=1.33) and m.g == 0.5
    with pytest.raises(InputError, match="g must lie"):
        m.replace(g=2.0)
    with pytest.raises(InputError, match="unknown Medium field"):
        m.replace(eta=1.4)


def test_dict_round_trip_is_json_ready():
    for m in (Medium(1.0, 0.01, 0.9), Medium(9.0, 1.0, 0.75, n=1.33, thickness_mm=0.2)):
        d = m.to_dict()
        assert list(d) == ["sigma_s", "sigma_a", "g", "n", "thickness_mm"]
        assert Medium.from_dict(json.loads(json.dumps(d, allow_nan=False))) == m
    assert Medium(1.0, 0.01, 0.9).to_dict()["thickness_mm"] is None
    assert Medium.from_dict({"sigma_s": 1.0, "sigma_a": 0.0, "g": 0.5}) == Medium(1.0, 0.0, 0.5)
    with pytest.raises(InputError, match="missing"):
        Medium.from_dict({"sigma_s": 1.0, "g": 0.5})
    with pytest.raises(InputError, match="unknown"):
        Medium.from_dict({"sigma_s": 1.0, "sigma_a": 0.0, "g": 0.5, "eta": 1.4})
    with pytest.raises(InputError):
        Medium.from_dict(1.0)


def test_as_medium_and_the_front_door():
    m = Medium(1.0, 0.1, 0.5)
    assert as_medium(m) is m
    with pytest.raises(TypeError, match="Medium"):
        as_medium(1.0)
    assert planeray.Medium is Medium and "Medium" in dir(planeray)


def test_docstring_examples():
    result = doctest.testmod(planeray.medium, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 5 and result.failed == 0


_valid = st.builds(
    Medium,
    sigma_s=st.floats(1e-6, 1e4),
    sigma_a=st.floats(0.0, 1e3),
    g=st.floats(-0.99, 0.99),
    n=st.floats(0.1, 4.0),
    thickness_mm=st.one_of(st.just(math.inf), st.floats(1e-3, 1e4)),
)


@settings(max_examples=200, deadline=None)
@given(_valid)
def test_reduced_round_trip_and_dict_round_trip_for_any_valid_medium(m):
    back = Medium.from_reduced(m.sigma_s_prime, m.sigma_a, m.g, n=m.n, thickness_mm=m.thickness_mm)
    assert back.sigma_s == pytest.approx(m.sigma_s, rel=1e-12)
    assert (back.sigma_a, back.g, back.n, back.thickness_mm) == (m.sigma_a, m.g, m.n, m.thickness_mm)
    assert Medium.from_dict(m.to_dict()) == m
    assert m.replace() == m
    assert 0.0 <= m.albedo <= 1.0 and m.transport_mfp_mm > 0.0
    assert m.sigma_s_prime == m.sigma_s * (1.0 - m.g)


# ----------------------------------------------------------------------------- its users
def test_mc_line_profile_of_a_medium_is_the_cached_result_of_the_same_parameters(tmp_path, monkeypatch):
    from planeray.mc import mc_line_profile

    monkeypatch.setenv("PLANERAY_CACHE", str(tmp_path))
    m = Medium(sigma_s=1.0, sigma_a=0.2, g=0.3, n=1.33, thickness_mm=4.0)
    kw = dict(n_photons=3_000, seed=1)
    fresh = mc_line_profile(m, **kw)
    stored = mc_line_profile(m, **kw, cache=True)
    # The cache key is the params dict of before Medium existed: same keys, order and
    # values, so entries written earlier (and the shipped tables) are still found.
    assert [p.name for p in (tmp_path / "mc").glob("*.npz")] == ["7fe25a03cb3c0f1f0e498f1c0672a6c3.npz"]
    assert list(fresh.params.items()) == [
        ("sigma_s", 1.0),
        ("sigma_a", 0.2),
        ("g", 0.3),
        ("n", 1.33),
        ("thickness", 4.0),
        ("n_photons", 3000),
        ("mm_per_row", 1.0),
        ("seed", 1),
        ("source_width_mm", 0.0),
        ("cutoff_mm", 202.0),
        ("diffusion_depth_mfp", 10.0),
    ]
    loaded = mc_line_profile(Medium(1, 0.2, 0.3, n=1.33, thickness_mm=4), **kw, cache=True)
    for p in (stored, loaded):
        assert p.values.tobytes() == fresh.values.tobytes()
        assert p.radiance.tobytes() == fresh.radiance.tobytes()
        assert p.total_reflectance == fresh.total_reflectance and p.params == fresh.params
    assert loaded.medium == m
    # Semi-infinite (and n = 1): "thickness" is None in the key, as before.
    semi = mc_line_profile(m.replace(n=1.0, thickness_mm=math.inf), **kw, cache=True)
    assert semi.params["thickness"] is None and semi.medium.semi_infinite
    assert (tmp_path / "mc" / "d909f24fbaf3e22c3733cacb42e4aed9.npz").exists()


def test_the_default_wax_medium_keys_the_shipped_table():
    from planeray.kernels import MC_KERNEL_REACH_ROWS
    from planeray.mc.cache import TABLES_DIR, cache_key
    from planeray.mc.engine import default_cutoff_mm
    from planeray.scenes.wax import WAX_MEDIUM

    assert WAX_MEDIUM == Medium.from_reduced(0.3, 0.003, g=0.8, n=1.4)
    canon = np.arange(-MC_KERNEL_REACH_ROWS, MC_KERNEL_REACH_ROWS + 1)
    params = dict(
        sigma_s=WAX_MEDIUM.sigma_s,
        sigma_a=0.003,
        g=0.8,
        n=1.4,
        thickness=None,
        n_photons=1_000_000,
        mm_per_row=0.3,
        seed=0,
        source_width_mm=0.0,
        cutoff_mm=default_cutoff_mm(WAX_MEDIUM, canon, mm_per_row=0.3),
        diffusion_depth_mfp=10.0,
    )
    assert (TABLES_DIR / f"{cache_key(params, canon)}.npz").exists()


def test_models_take_a_medium_and_refuse_loose_floats():
    from planeray.kernels import line_kernel
    from planeray.mc import mc_line_profile, mc_point_profile
    from planeray.mc.diffusion import (
        dipole_line_kernel,
        dipole_reflectance,
        dipole_total_reflectance,
    )
    from planeray.mc.mitsuba_ref import mitsuba_line_profile, single_scattering_radiance

    with pytest.raises(TypeError):
        mc_line_profile(1.0, 0.1, 0.5)
    with pytest.raises(TypeError, match="Medium"):
        mc_point_profile({"sigma_s": 1.0, "sigma_a": 0.1, "g": 0.5}, n_photons=10)
    slab = Medium(1.0, 0.1, 0.5, thickness_mm=2.0)
    u = np.arange(-3, 4)
    # The dipole and the Mitsuba scene model half-spaces only (the latter index-matched).
    for call in (
        lambda: dipole_total_reflectance(slab),
        lambda: dipole_reflectance(slab, [1.0]),
        lambda: dipole_line_kernel(slab, u, mm_per_row=1.0),
        lambda: line_kernel(slab, u, mm_per_row=1.0, model="dipole"),
        lambda: mitsuba_line_profile(Medium(1.0, 0.1, 0.5, n=1.4), u, mm_per_row=1.0),
        lambda: single_scattering_radiance(slab, source_width_mm=1.0),
    ):
        with pytest.raises(InputError):
            call()
    # The dipole sees only sigma_a, sigma_s' and n: media of equal sigma_s' agree.
    a = dipole_line_kernel(Medium.from_reduced(0.5, 0.01, g=0.0, n=1.3), u, mm_per_row=0.5)
    b = dipole_line_kernel(Medium(0.5, 0.01, 0.0, n=1.3), u, mm_per_row=0.5)
    assert a.tobytes() == b.tobytes()


def test_wax_scene_takes_a_medium_or_its_old_keywords():
    from planeray.scenes import make_scene
    from planeray.scenes.wax import WAX_MEDIUM

    kw = dict(projector_rows=90, seed=0, kernel="dipole", band_rows=16)
    default = make_scene("wax", (16, 16), **kw)
    same = make_scene("wax", (16, 16), **kw, medium=WAX_MEDIUM, sigma_s_prime=0.3, eta=1.4)
    assert same.params == default.params
    assert same.transport.dense.tobytes() == default.transport.dense.tobytes()
    other = Medium.from_reduced(0.6, 0.01, g=0.5, n=1.33)
    by_medium = make_scene("wax", (16, 16), **kw, medium=other)
    by_keywords = make_scene("wax", (16, 16), **kw, sigma_s_prime=0.6, sigma_a=0.01, g=0.5, eta=1.33)
    assert by_medium.params == by_keywords.params
    assert by_medium.params["sigma_s_prime"] == other.sigma_s_prime and by_medium.params["eta"] == 1.33
    assert by_medium.transport.dense.tobytes() == by_keywords.transport.dense.tobytes()
    assert by_medium.transport.dense.tobytes() != default.transport.dense.tobytes()
