"""Ambient light in the camera's band (planeray.skin.ambient) against independent numbers."""

from __future__ import annotations

import numpy as np
import pytest

from planeray.skin.ambient import (
    AMBIENT_LEVELS,
    FRAME_PERIOD_US,
    PROJECTOR_FIELD_M2,
    PROJECTOR_POWER_W,
    ambient_e_per_us,
    ambient_table,
    band_irradiance_w_m2,
    luminosity,
    relative_spectrum,
)


def _efficacy(kind):
    lam = np.arange(100.0, 100_000.0, 0.5)
    s = relative_spectrum(kind, lam)
    return 683.0 * np.sum(luminosity(lam) * s) / np.sum(s)


def test_luminous_efficacy_of_the_spectra():
    # a 5800 K blackbody: 93 lm/W (e.g. Wikipedia "Luminous efficacy", from Planck's law and the CIE V)
    assert _efficacy("sun") == pytest.approx(93.0, rel=0.03)
    # phosphor-converted white LEDs: about 300-350 lm/W of radiation
    assert 300.0 < _efficacy("led") < 350.0


def test_luminosity_function_peaks_near_555_nm():
    lam = np.arange(380.0, 781.0, 1.0)
    assert abs(lam[np.argmax(luminosity(lam))] - 557.0) <= 3
    assert luminosity(555.0) == pytest.approx(1.0, abs=0.02)
    assert luminosity(650.0) == pytest.approx(0.107, abs=0.02)  # CIE 1924: 0.107


def test_band_irradiance_scales_and_sunlight_number():
    assert band_irradiance_w_m2(0.0, "sun", 638.0) == 0.0
    a = band_irradiance_w_m2(1000.0, "sun", 638.0)
    assert band_irradiance_w_m2(3000.0, "sun", 638.0) == pytest.approx(3 * a)
    assert band_irradiance_w_m2(1000.0, "sun", 638.0, filter_fwhm_nm=20.0) == pytest.approx(2 * a, rel=0.02)
    # 100 klx of sunlight: ~1.3 W/m^2/nm at 638 nm (ASTM G173 direct normal at 640 nm: about 1.3-1.4)
    assert band_irradiance_w_m2(100_000.0, "sun", 638.0) / 10.0 == pytest.approx(1.3, rel=0.1)


def test_conversion_to_the_camera_model():
    e = band_irradiance_w_m2(10_000.0, "sun", 850.0)
    expected = 6000.0 / FRAME_PERIOD_US * e / (PROJECTOR_POWER_W / PROJECTOR_FIELD_M2)
    assert ambient_e_per_us(10_000.0, "sun", 850.0) == pytest.approx(expected)
    assert ambient_e_per_us(10_000.0, "sun", 850.0, laser_electrons=3000.0) == pytest.approx(expected / 2)
    rows = ambient_table(638.0)
    assert [r["name"] for r in rows] == list(AMBIENT_LEVELS)
    # LED light has next to nothing at 850 nm; sunlight does
    assert ambient_e_per_us(40_000.0, "led", 850.0) < 1e-3 * ambient_e_per_us(40_000.0, "led", 638.0)
    assert ambient_e_per_us(100_000.0, "sun", 850.0) > 0.5 * ambient_e_per_us(100_000.0, "sun", 638.0)
