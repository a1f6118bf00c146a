"""identical_files: byte-identical takes are grouped, gzipped or not; distinct files are not."""

from __future__ import annotations

import gzip

import pytest

from humancal.mocap import MocapFormatError, identical_files


def test_identical_files_groups_the_same_content_gzipped_or_not(tmp_path):
    take, other = b"HIERARCHY\nROOT hip\n" * 100, b"HIERARCHY\nROOT pelvis\n" * 100
    (tmp_path / "a.bvh").write_bytes(take)
    (tmp_path / "b.bvh").write_bytes(other)
    with gzip.open(tmp_path / "c.bvh.gz", "wb") as stream:
        stream.write(take)
    (tmp_path / "d.bvh").write_bytes(take + b"\n")  # one byte more: a different file
    paths = [tmp_path / n for n in ("a.bvh", "b.bvh", "c.bvh.gz", "d.bvh")]

    assert identical_files(paths) == [(tmp_path / "a.bvh", tmp_path / "c.bvh.gz")]
    assert identical_files(paths[1:]) == []
    assert identical_files([str(p) for p in reversed(paths)]) == [(tmp_path / "c.bvh.gz", tmp_path / "a.bvh")]


def test_identical_files_names_a_bad_or_truncated_gzip(tmp_path):
    (tmp_path / "x.bvh.gz").write_bytes(b"not gzip at all")
    with pytest.raises(MocapFormatError, match=r"x\.bvh\.gz: a \.gz name, but not a whole gzip stream"):
        identical_files([tmp_path / "x.bvh.gz"])
    whole = gzip.compress(b"HIERARCHY\n" * 1000)
    (tmp_path / "cut.bvh.gz").write_bytes(whole[: len(whole) // 2])
    with pytest.raises(MocapFormatError, match=r"cut\.bvh\.gz"):
        identical_files([tmp_path / "cut.bvh.gz"])
    with pytest.raises(FileNotFoundError, match="missing.bvh"):
        identical_files([tmp_path / "missing.bvh"])
