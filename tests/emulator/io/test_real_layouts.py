"""The dataset layouts people have (emulator.io.layout): the shared sample, a clone of the
BorealHDR repository, symlinked zips; the calibration chosen by the recording's date.

Layouts are built in tmp dirs from the shared sample's files (symlinks, or small copies).
"""

from __future__ import annotations

import datetime as dt
import json
import os
import zipfile
from pathlib import Path

import pytest

from emulator.commands.cli import main
from emulator.io.borealhdr import find_response, load_sequence, sequence_response
from emulator.io.layout import choose_stereo_calibration, recording_date, search_roots
from emulator.metrics.stereo import choose_calibration

from tests.conftest import SAMPLE, SAMPLE_SEQ, missing_shared

NAME = SAMPLE_SEQ.name
CALIB = SAMPLE / "calibration"


@pytest.fixture(scope="module")
def sample():
    if not SAMPLE_SEQ.is_dir():
        missing_shared(f"shared BorealHDR sample not found at {SAMPLE_SEQ}")
    return SAMPLE_SEQ


def first_cycle_recording(dest: Path, n_files: int = 12) -> Path:
    """A recording with the sample's first ``n_files`` shots per camera, symlinked."""
    for cam in ("camera_left", "camera_right"):
        files = sorted((SAMPLE_SEQ / cam).glob("*/*.png"), key=lambda p: int(p.stem))[:n_files]
        for f in files:
            (dest / cam / f.parent.name).mkdir(parents=True, exist_ok=True)
            (dest / cam / f.parent.name / f.name).symlink_to(f)
    return dest


def upstream_clone(root: Path) -> Path:
    """A clone of the BorealHDR repository: calibration_files/ and data_sample/."""
    clone = root / "BorealHDR"
    files = clone / "calibration_files"
    vo = files / "calibration_vo"
    for month in ("april_2023", "september_2023", "september_2023_modified"):
        (vo / month).mkdir(parents=True)
        src = CALIB / ("april_2023" if month.startswith("april") else "september_2023")
        for side in ("left.yaml", "right.yaml"):
            (vo / month / side).symlink_to(src / side)
    (files / "pcalib_inside1.txt").symlink_to(CALIB / "pcalib_inside1.txt")
    # upstream also has pcalib_2024.txt, which sorts first; the reference code loads inside1
    (files / "pcalib_2024.txt").write_text((CALIB / "pcalib_inside1.txt").read_text())
    first_cycle_recording(clone / "data_sample" / NAME)
    return clone


def test_recording_date_from_name_and_timestamps():
    assert recording_date(f"/x/{NAME}")[0] == dt.date(2023, 9, 25)
    assert recording_date("/x/backpack_2023-04-20-09-29-14.zip")[0] == dt.date(2023, 4, 20)
    date, source = recording_date("/x/seq", 1695668703364771328)
    assert date == dt.date(2023, 9, 25) and "timestamp" in source
    assert recording_date("/x/seq", 1_700_000)[0] is None  # synthetic clock near 0: no date


def test_sample_layout_chooses_september(sample):
    choice = choose_stereo_calibration(sample)
    assert choice.folder == CALIB / "september_2023"
    assert "month" in choice.reason and choice.date == "2023-09-25"
    assert str(CALIB / "april_2023") in choice.candidates
    assert find_response(sample) == CALIB / "pcalib_inside1.txt"


def test_upstream_clone_layout(sample, tmp_path):
    clone = upstream_clone(tmp_path)
    rec = clone / "data_sample" / NAME
    assert find_response(rec) == clone / "calibration_files" / "pcalib_inside1.txt"
    choice = choose_stereo_calibration(rec)
    assert choice.folder == clone / "calibration_files" / "calibration_vo" / "september_2023"  # not _modified
    assert len(choice.candidates) == 3
    seq = load_sequence(rec)
    assert sequence_response(seq).name == str(clone / "calibration_files" / "pcalib_inside1.txt")
    # an April recording in the clone takes april_2023; a June one the latest before it
    (clone / "data_sample" / "backpack_2023-04-20-09-29-14").mkdir()
    assert choose_stereo_calibration(clone / "data_sample" / "backpack_2023-04-20-09-29-14").folder.name == "april_2023"
    (clone / "data_sample" / "backpack_2023-06-01-10-00-00").mkdir()
    june = choose_stereo_calibration(clone / "data_sample" / "backpack_2023-06-01-10-00-00")
    assert june.folder.name == "april_2023" and "latest" in june.reason


def test_upstream_clone_runs_from_the_cli(sample, tmp_path, capsys):
    clone = upstream_clone(tmp_path)
    out = tmp_path / "run"
    code = main(["run", str(clone / "data_sample" / NAME), "--methods", "fixed", "-o", str(out), "--no-progress"])
    _, err = capsys.readouterr()
    assert code == 0, err
    run = json.loads((out / "run.json").read_text())
    # recorded resolved: the clone's link to the sample's file, not the pcalib_2024.txt copy
    assert run["response"] == str((clone / "calibration_files" / "pcalib_inside1.txt").resolve())


def _small_zip(path: Path) -> Path:
    files = sorted((SAMPLE_SEQ / "camera_left").glob("*/*.png"), key=lambda p: int(p.stem))[:2]
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as z:
        for f in files:
            z.write(f, f"{NAME}/camera_left/{f.parent.name}/{f.name}")
    return path


def test_symlinked_zip_finds_its_response_beside_target_and_beside_link(sample, tmp_path):
    # the zip lives in a store with calibration/; the dataset root holds only a link to it
    store = tmp_path / "store"
    (store / "calibration").mkdir(parents=True)
    (store / "calibration" / "pcalib_inside1.txt").symlink_to(CALIB / "pcalib_inside1.txt")
    target = _small_zip(store / f"{NAME}.zip")
    dataset = tmp_path / "dataset"
    dataset.mkdir()
    link = dataset / f"{NAME}.zip"
    link.symlink_to(target)
    assert search_roots(link)[0] == dataset  # beside the link first
    assert find_response(link) == store / "calibration" / "pcalib_inside1.txt"
    seq = load_sequence(link)
    assert sequence_response(seq).name == str(store / "calibration" / "pcalib_inside1.txt")
    # and the other way round: calibration beside the link, nothing beside the target
    (store / "calibration" / "pcalib_inside1.txt").unlink()
    (dataset / "calibration").mkdir()
    (dataset / "calibration" / "pcalib_inside1.txt").symlink_to(CALIB / "pcalib_inside1.txt")
    assert find_response(link) == dataset / "calibration" / "pcalib_inside1.txt"
    # a zip's stereo calibration: september_2023 beside the link, chosen from the zip's name
    (dataset / "calibration" / "september_2023").symlink_to(CALIB / "september_2023")
    assert choose_stereo_calibration(link).folder == dataset / "calibration" / "september_2023"


def test_nothing_found_is_one_clear_error(tmp_path):
    from emulator.errors import CalibrationError

    rec = tmp_path / "a" / "b" / "c" / "rec"
    rec.mkdir(parents=True)
    assert find_response(rec) is None
    with pytest.raises(CalibrationError, match="no folder with left.yaml and right.yaml.*pass --calibration"):
        choose_calibration(rec)
    # two undated calibrations and an undated recording: the date cannot choose
    for month in ("april_2023", "september_2023"):
        (tmp_path / "a" / "b" / "c" / "calibration" / month).mkdir(parents=True)
        for side in ("left.yaml", "right.yaml"):
            (tmp_path / "a" / "b" / "c" / "calibration" / month / side).write_text("x")
    with pytest.raises(CalibrationError, match="2 calibrations found.*does not choose"):
        choose_calibration(rec)
    assert choose_calibration(rec, first_timestamp_ns=1695668703364771328).folder.name == "september_2023"
