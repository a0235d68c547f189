"""A folder's EXR file this user may not read (dbench/datasets/folders/exr_layers.py)."""
from pathlib import Path

import numpy as np
import pytest

from exr_files import write_rgb as _rgb  # tests/exr_files.py


def test_an_exr_this_user_may_not_read_is_refused_before_openexr_opens_it(tmp_path,
                                                                           monkeypatch):
    """OpenEXR's C library printed its own line to stderr before dbench's; the file is refused
    first, as a PermissionError the command line turns into one line (exit 2). (Tests run as
    root, which reads through permissions: os.access is stubbed.)"""
    from dbench.datasets.folders import exr_layers

    path = tmp_path / "v_0004.hdr.exr"
    _rgb(path, np.ones((4, 6, 3), np.float32))
    monkeypatch.setattr(exr_layers.os, "access", lambda p, mode: Path(p) != path)
    for read in (exr_layers.exr_header, exr_layers.read_channels):
        with pytest.raises(PermissionError) as info:
            read(path)
        assert info.value.filename == str(path)
