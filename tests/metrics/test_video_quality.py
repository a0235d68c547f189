"""ColorVideoVDP on linear HDR videos (dbench/metrics/video_quality.py): the JOD scale, the
temporal part, offline operation, the buffer checks and the sequence column."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from dbench.errors import DbenchInputError
from dbench.metrics import video_quality as vq

T, H, W = 12, 32, 32


def _reference(frames: int = T, seed: int = 0) -> np.ndarray:
    """A textured scene drifting one pixel per frame, values around the tone map's white."""
    rng = np.random.default_rng(seed)
    tex = 0.2 + 0.6 * rng.random((H, W + frames, 3))
    return np.stack([tex[:, t:t + W] for t in range(frames)])


def test_identical_videos_score_ten():
    ref = _reference()
    assert vq.cvvdp_jod(ref, ref, fps=30) == pytest.approx(10.0, abs=1e-3)
    assert vq.cvvdp_jod(ref[:1], ref[:1]) == pytest.approx(10.0, abs=1e-3)  # one frame: image


def test_noise_lowers_the_score_monotonically():
    ref = _reference()
    rng = np.random.default_rng(1)
    noise = rng.standard_normal(ref.shape)
    scores = [vq.cvvdp_jod(np.maximum(ref * (1 + s * noise), 0), ref) for s in
              (0.0, 0.02, 0.05, 0.1, 0.2)]
    assert all(a > b for a, b in zip(scores, scores[1:])), scores
    assert scores[-1] < 9.0


def test_flicker_costs_more_than_a_static_error_of_the_same_rmse():
    # the same ±5 % gain on every frame: fixed (static) or with a random sign per frame
    # (flicker); every frame's RMSE is the same in both
    ref = _reference(16)
    signs = np.where(np.random.default_rng(2).random(16) < 0.5, -1.0, 1.0)
    static = ref * 1.05
    flicker = ref * (1 + 0.05 * signs)[:, None, None, None]
    np.testing.assert_allclose(np.sqrt(((static - ref) ** 2).mean(axis=(1, 2, 3))),
                               np.sqrt(((flicker - ref) ** 2).mean(axis=(1, 2, 3))))
    q_static, q_flicker = vq.cvvdp_jod(static, ref), vq.cvvdp_jod(flicker, ref)
    assert q_flicker < q_static - 0.5, (q_static, q_flicker)


def test_the_frame_rate_matters_only_for_what_changes_over_time():
    # a still scene; an error pattern of 8-px blocks, frozen or drawn anew every frame
    ref = np.repeat(_reference(1), 16, axis=0)
    rng = np.random.default_rng(3)

    def blocks(n):
        return np.repeat(np.repeat(rng.standard_normal((n, H // 8, W // 8, 1)), 8, 1), 8, 2)

    frozen, fresh = ref * (1 + 0.05 * blocks(1)), ref * (1 + 0.05 * blocks(16))
    q = {(name, fps): vq.cvvdp_jod(x, ref, fps=fps)
         for name, x in (("frozen", frozen), ("fresh", fresh)) for fps in (10, 60)}
    assert q["frozen", 10] == pytest.approx(q["frozen", 60], abs=1e-3)
    assert abs(q["fresh", 10] - q["fresh", 60]) > 0.5, q


def test_deterministic_and_non_finite_output_is_nan():
    ref = _reference()
    out = ref * (1 + 0.1 * np.random.default_rng(4).standard_normal(ref.shape))
    assert vq.cvvdp_jod(out, ref) == vq.cvvdp_jod(out, ref)
    for bad in (np.nan, np.inf):
        x = out.copy()
        x[3, 5, 7, 1] = bad
        assert np.isnan(vq.cvvdp_jod(x, ref))
    assert np.isfinite(vq.cvvdp_jod(np.full_like(ref, 3e38), ref))  # clipped at the peak


@pytest.mark.parametrize("kwargs, buffer", [
    ({"output": np.zeros((T, H, W + 1, 3))}, "output"),
    ({"output": np.zeros((T, H, W))}, "output"),
    ({"reference": np.zeros((H, W, 3)), "output": np.zeros((H, W, 3))}, "reference"),
    ({"reference": np.zeros((T, H, W, 4)), "output": np.zeros((T, H, W, 4))}, "reference"),
    ({"reference": np.zeros((T, 1, W, 3)), "output": np.zeros((T, 1, W, 3))}, "reference"),
    ({"reference": np.full((T, H, W, 3), np.nan)}, "reference"),
    ({"output": None}, "output"),
    ({"fps": 0}, "fps"),
    ({"fps": float("nan")}, "fps"),
    ({"display": "no-such-display"}, "display"),
    ({"ev": float("inf")}, "ev"),
])
def test_bad_inputs_name_the_buffer(kwargs, buffer):
    ref = _reference()
    args = {"output": ref, "reference": ref, **kwargs}
    with pytest.raises(DbenchInputError, match=rf"^{buffer}:"):
        vq.cvvdp_jod(**args)


_OFFLINE = r"""
import socket, sys
def refuse(*a, **k):
    raise OSError("network blocked")
socket.socket.connect = refuse
socket.socket.connect_ex = refuse
socket.create_connection = refuse
socket.getaddrinfo = refuse
import numpy as np
from dbench.metrics.video_quality import cvvdp_jod
ref = np.random.default_rng(0).random((6, 24, 24, 3))
print(cvvdp_jod(ref * (0.8 + 0.4 * ref), ref), cvvdp_jod(ref, ref))
"""


def test_runs_with_the_network_blocked(tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.upper().startswith(("CVVDP", "HF_"))}
    dead = "http://127.0.0.1:9"  # the discard port: nothing listens there
    env.update(HTTP_PROXY=dead, HTTPS_PROXY=dead, http_proxy=dead, https_proxy=dead,
               HF_HOME=str(tmp_path / "hf"))
    run = subprocess.run([sys.executable, "-c", _OFFLINE], env=env, capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    a, b = map(float, run.stdout.split())
    assert b == pytest.approx(10.0, abs=1e-3) and a < 10.0
    assert not (tmp_path / "hf").exists()  # nothing was fetched into a hub cache


def test_auto_rule_and_sequence_column():
    from dbench.run.sequence_run import run_sequence
    from dbench.synthetic import synthetic_sequence

    assert vq.use_cvvdp(24, 128, 128) and not vq.use_cvvdp(25, 128, 128)
    assert vq.use_cvvdp(10**6, 720, 1280, wanted=True) and not vq.use_cvvdp(1, 2, 2, False)
    seq = synthetic_sequence(16, 24, frames=10)
    on = run_sequence("accumulate", seq, keep_outputs=True)
    assert 0 < on.summary["cvvdp"] < 10
    refs = [f.reference for f in seq]
    # the frames after the 8-frame warm-up, as the sequence's other means
    assert on.summary["cvvdp"] == vq.cvvdp_jod(np.stack(on.outputs[8:]), np.stack(refs[8:]))
    assert "cvvdp" not in run_sequence("accumulate", seq, cvvdp=False).summary
    # no more frames than the warm-up: all of them
    assert vq.sequence_cvvdp(refs[:3], refs[:3], warmup=8)["cvvdp"] == pytest.approx(10.0)
    assert vq.sequence_cvvdp(refs[:3], refs[:3], warmup=8, wanted=False) == {}
    with pytest.raises(DbenchInputError, match="^outputs:"):
        vq.sequence_cvvdp(refs[:2], refs[:3], warmup=0)


def test_sequence_cell_and_sweep_table_carry_the_column():
    from dbench import registry
    from dbench.run import harness
    from dbench.report import tables
    from dbench.synthetic import synthetic_sequence

    cell = harness.run_sequence_cell(registry.get("accumulate"), synthetic_sequence(16, 24, 10))
    assert 0 < cell.metrics["cvvdp"] < 10 and "cvvdp_ci" in cell.metrics
    base = {"status": "ok", "scene": "s", "method": "m", "spp": 1, "rmse": 0.1}
    df = tables.cells_frame([{**base, "cvvdp": 8.5, "cvvdp_ci": 0.2}])
    assert df.loc[0, "cvvdp"] == 8.5 and df.loc[0, "cvvdp_ci"] == 0.2
    assert "cvvdp" not in tables.cells_frame([base]).columns  # steady cells: no column


def test_definition_states_display_luminance_and_rate():
    text = vq.CVVDP_DEFINITION
    assert "standard_hdr_linear" in text and "203" in text and "30 fps" in text
    assert json.dumps(text)  # one plain line for reports
    assert "\n" not in text
