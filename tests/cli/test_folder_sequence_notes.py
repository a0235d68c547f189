"""A folder sequence's input facts and doubts are found frame by frame (dbench/cli/run.py
``_input_notes``): a reference that is no reference on one frame is named with its frame,
facts the frames share are said once."""
import numpy as np

from dbench.cli import main
from dbench.run.scene_run import input_notes as _input_notes
from dbench.data import Frame
from dbench.datasets.folders.export import export_frame


def test_notes_name_the_frames_they_hold_for(capsys):
    metas = [{"reference_warning": "ref A", "layers_read": ["color"]},
             {"layers_read": ["color"]},
             {"reference_warning": "ref A", "layers_read": ["color"]},
             {"reference_warning": "ref B", "layers_read": ["color", "albedo"]}]
    settings = {}
    notes = _input_notes(metas, settings)
    assert notes == ["frames 0, 2: ref A", "frame 3: ref B"]
    assert settings["layers read"] == "frames 0-2: color; frame 3: color; albedo"
    assert "warning: frames 0, 2: ref A" in capsys.readouterr().err
    settings = {}
    assert _input_notes([{"normal_warning": "n"}] * 3, settings) == ["n"]


def test_a_bad_reference_on_one_frame_of_a_folder_is_reported(tmp_path):
    rng = np.random.default_rng(0)
    folder = tmp_path / "seq"
    for k in range(3):
        truth = rng.uniform(0.2, 1.0, (12, 16, 3)).astype(np.float32)
        color = (truth * (1 + 0.3 * rng.standard_normal(truth.shape))).astype(np.float32)
        ref = color if k == 2 else truth  # frame 2's "reference" is its noisy input
        export_frame(Frame(color=color, motion=np.zeros((12, 16, 2), np.float32),
                           reference=ref, meta={}), folder, "walk", 4, frame_index=k)
    out = tmp_path / "run"
    assert main(["run", "--method", "noisy", "--scene", str(folder), "--spp", "4", "--out",
                 str(out), "--quiet"]) == 0
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "frame 2: " in report and "noisy input" in report
