"""
Fig. 15: a pulse from short-range indirect light
================================================

Blood volume under the skin changes with each heartbeat, and so does the light scattered a few
millimetres through the tissue. A live video of the short-range indirect band (a fixed delay) is
magnified by Eulerian video magnification (Wu et al. 2012) and its heart rate read from the
spectrum (paper Fig. 15a). The video here is simulated: 20 s of a 48x48 forearm at 72 beats
per minute, with breathing, arm motion and camera noise.

Command line: ``planeray skin video --out arm.tif``, ``planeray skin pulse arm.tif --out pulse``;
``planeray skin pulse-report`` runs Fig. 15.
"""

from planeray.figures.pulse import pulse_signal_figure
from planeray.pulse.analysis import analyze_pulse
from planeray.pulse.simulate import LiveSettings, simulate_live, skin_builder

capture = simulate_live(
    LiveSettings(seconds=20.0, bpm=72.0),
    build=skin_builder((48, 48), projector_rows=192, seed=0),
    methods=("indirect",),
    seed=0,
)
video = capture.videos["indirect"]
print(f"{video.frames.shape[0]} frames of {video.frames.shape[1:]} pixels at {video.fps:g} fps")

result = analyze_pulse(video)
e = result.estimate
print(
    f"heart rate {e.rate_bpm:.1f} bpm (truth {capture.truth['mean_rate_bpm']:.1f}), SNR {e.snr_db:.1f} dB, detected: {e.detected}"
)
fig = pulse_signal_figure(
    result.time_s, result.signal, e, raw=result.raw_signal, truth_bpm=capture.truth["mean_rate_bpm"]
)
