"""ASF/AMC reader on a hand-written two-bone skeleton whose forward kinematics is worked out by hand."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from humancal.mocap import R_ZUP_FROM_YUP, MocapFormatError, asf_rest_positions, read_amc, read_asf

# root -> thigh (rest direction +x, length 10, local frame turned 90 deg about z, dof rx)
#      -> shin  (rest direction -y, length 5, local frame = world, dof rx rz)
ASF = """# test skeleton
:version 1.10
:name VICON
:units
  mass 1.0
  length 0.45
  angle deg
:documentation
   hand-written
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name thigh
     direction 2 0 0
     length 10
     axis 0 0 90  XYZ
    dof rx
    limits (-160.0 20.0)
  end
  begin
     id 2
     name shin
     direction 0 -1 0
     length 5
     axis 0 0 0 XYZ
    dof rx rz
    limits (-10.0 170.0)
           (-10.0 170.0)
  end
:hierarchy
  begin
    root thigh
    thigh shin
  end
"""

AMC_HEADER = "#!OML:ASF test.asf\r\n:FULLY-SPECIFIED\r\n:DEGREES\r\n"


def amc_text(frames: list[tuple[str, str, str]]) -> str:
    lines = []
    for k, (root, thigh, shin) in enumerate(frames, start=1):
        lines += [str(k), f"root {root}", f"thigh {thigh}", f"shin {shin}"]
    return AMC_HEADER + "\r\n".join(lines) + "\r\n"  # CMU files have CRLF line ends


def write(tmp_path: Path, name: str, text: str, compress: bool = False) -> Path:
    path = tmp_path / (name + (".gz" if compress else ""))
    path.write_bytes(gzip.compress(text.encode()) if compress else text.encode())
    return path


@pytest.fixture
def skeleton(tmp_path):
    return read_asf(write(tmp_path, "99.asf", ASF))


def to_file_axes(points_zup: np.ndarray) -> np.ndarray:
    return points_zup @ R_ZUP_FROM_YUP  # inverse of the reader's (x, y, z) -> (x, -z, y)


def test_read_asf(skeleton):
    assert skeleton.length_unit == 0.45 and skeleton.angle_unit == "deg"
    assert skeleton.metres_per_unit == pytest.approx(0.0254 / 0.45)
    assert skeleton.root_order == ("tx", "ty", "tz", "rx", "ry", "rz")
    assert [b.name for b in skeleton.bones] == ["thigh", "shin"]
    assert [b.parent for b in skeleton.bones] == [-1, 0]
    assert skeleton.bones[0].direction == (1.0, 0.0, 0.0)  # normalised
    assert skeleton.bones[1].dof == ("rx", "rz")
    assert skeleton.joint_names == ("root", "thigh", "shin") and skeleton.parents == (-1, 0, 1)


def test_rest_pose(skeleton):
    rest = to_file_axes(asf_rest_positions(skeleton)) / skeleton.metres_per_unit
    np.testing.assert_allclose(rest, [[0, 0, 0], [10, 0, 0], [10, -5, 0]], atol=1e-12)


def test_fk_by_hand(tmp_path, skeleton):
    # Frame 2: root at (1, 2, 3) turned Ry(90); thigh rx = 90 in its frame C = Rz(90), so
    #   L_thigh = C Rx(90) C^-1 = Ry(90) (a turn about C's x axis, which is world y)
    #   W_thigh = Ry(90) Ry(90) = Ry(180): thigh end = (1,2,3) + 10 * (-1, 0, 0) = (-9, 2, 3)
    #   (the transposed convention C^-1 M C would give L = Ry(-90), W = I and (11, 2, 3))
    # shin dof rx = 90 then rz = 90, applied in that order: M = Rz(90) Rx(90); M (0,-1,0) = (0, 0, -1)
    #   (the other order would give (1, 0, 0)); W_shin = Ry(180) M: (0, 0, 1): shin end = (-9, 2, 8)
    path = write(tmp_path, "99_01.amc", amc_text([("0 0 0 0 0 0", "0", "0 0"), ("1 2 3 0 90 0", "90", "90 90")]))
    clip = read_amc(path, skeleton, metres_per_unit=1.0, floor_percentile=None)
    got = to_file_axes(clip.positions_world_m)
    np.testing.assert_allclose(got[0], [[0, 0, 0], [10, 0, 0], [10, -5, 0]], atol=1e-12)
    np.testing.assert_allclose(got[1], [[1, 2, 3], [-9, 2, 3], [-9, 2, 8]], atol=1e-12)
    assert clip.fps == 120.0 and clip.frames == 2 and clip.name == "99_01" and clip.subject == "99"


def test_root_rotation_order(tmp_path, skeleton):
    # Root RX = 90 then RZ = 90 (applied in the ASF order): R = Rz(90) Rx(90); thigh rest (10, 0, 0) -> (0, 10, 0).
    path = write(tmp_path, "99_02.amc", amc_text([("0 0 0 90 0 90", "0", "0 0")]))
    got = to_file_axes(read_amc(path, skeleton, metres_per_unit=1.0, floor_percentile=None).positions_world_m)
    np.testing.assert_allclose(got[0, 1], [0, 10, 0], atol=1e-12)


def test_default_units_axes_and_floor(tmp_path, skeleton):
    path = write(tmp_path, "99_03.amc", amc_text([("0 7 0 0 0 0", "0", "0 0")]), compress=True)
    clip = read_amc(path, skeleton)
    unit = 0.0254 / 0.45
    # file (x, y, z) -> (x, -z, y); the shin end (file y = 2) is lowest and goes to z = 0
    np.testing.assert_allclose(clip.positions_world_m[0], np.array([[0, 0, 5], [10, 0, 5], [10, 0, 0]]) * unit,
                               atol=1e-12)


def test_radians_keyword(tmp_path, skeleton):
    text = amc_text([("0 0 0 0 0 0", f"{np.pi / 2}", "0 0")]).replace(":DEGREES", ":RADIANS")
    got = to_file_axes(read_amc(write(tmp_path, "r.amc", text), skeleton, metres_per_unit=1.0,
                                floor_percentile=None).positions_world_m)
    # thigh rx = 90 deg about world y (see test_fk_by_hand): (10, 0, 0) -> (0, 0, -10)
    np.testing.assert_allclose(got[0, 1], [0, 0, -10], atol=1e-12)


# ---- bad inputs -----------------------------------------------------------------------------------


def amc_error(tmp_path: Path, skeleton, text: str) -> MocapFormatError:
    path = write(tmp_path, "bad.amc", text)
    with pytest.raises(MocapFormatError) as info:
        read_amc(path, skeleton)
    assert str(path) in str(info.value)
    return info.value


def test_amc_wrong_number_of_values(tmp_path, skeleton):
    err = amc_error(tmp_path, skeleton, amc_text([("0 0 0 0 0 0", "0", "0 0"), ("0 0 0 0 0 0", "0 1", "0 0")]))
    assert err.line == 10 and "thigh has 2 values; expected 1" in str(err)


def test_amc_unknown_bone(tmp_path, skeleton):
    err = amc_error(tmp_path, skeleton, amc_text([("0 0 0 0 0 0", "0", "0 0")]).replace("shin", "tail"))
    assert err.line == 7 and "bone 'tail' is not an animated bone of 99.asf" in str(err)


def test_amc_truncated_last_frame(tmp_path, skeleton):
    text = amc_text([("0 0 0 0 0 0", "0", "0 0")] * 3)
    err = amc_error(tmp_path, skeleton, "\r\n".join(text.split("\r\n")[:-2]))
    assert "frame 3 lacks shin" in str(err) and err.line == 14


def test_amc_frame_numbers_out_of_sequence(tmp_path, skeleton):
    text = amc_text([("0 0 0 0 0 0", "0", "0 0")] * 2).replace("\r\n2\r\n", "\r\n3\r\n")
    err = amc_error(tmp_path, skeleton, text)
    assert err.line == 8 and "expected frame number 2, found 3" in str(err)


def test_amc_nan(tmp_path, skeleton):
    err = amc_error(tmp_path, skeleton, amc_text([("0 0 0 0 0 0", "0", "0 0"), ("0 0 nan 0 0 0", "0", "0 0")]))
    assert err.line == 8 and "non-finite value for root" in str(err)


def test_amc_without_frames(tmp_path, skeleton):
    err = amc_error(tmp_path, skeleton, AMC_HEADER)
    assert "no frames" in str(err)


def test_asf_errors(tmp_path):
    cases = [
        (ASF.replace("direction 0 -1 0", "direction 0 -1"), 28, "expected 3 numbers for bone direction"),
        (ASF.replace("dof rx rz", "dof rx tz"), 31, "unsupported dof ['tz']"),
        (ASF.replace("thigh shin", "thigh shank"), 38, "hierarchy names bone 'shank', absent from :bonedata"),
        (ASF.replace("axis 0 0 0 XYZ", "axis 0 0 0 XXY"), 30, "expected an axis order such as XYZ"),
        (ASF.replace("angle deg", "angle grad"), 7, "expected ':units angle deg|rad'"),
    ]
    for k, (text, line, message) in enumerate(cases):
        path = write(tmp_path, f"bad{k}.asf", text)
        with pytest.raises(MocapFormatError) as info:
            read_asf(path)
        assert str(path) in str(info.value) and info.value.line == line and message in str(info.value), info.value
    no_root = ASF.replace("   order TX TY TZ RX RY RZ\n", "")
    with pytest.raises(MocapFormatError, match="no ':root' section with an 'order' line"):
        read_asf(write(tmp_path, "noroot.asf", no_root))
    orphan = ASF.replace("    thigh shin\n", "")
    with pytest.raises(MocapFormatError, match="not reachable from root in ':hierarchy': shin"):
        read_asf(write(tmp_path, "orphan.asf", orphan))


def test_amc_fast_and_careful_readers_agree(tmp_path, skeleton):
    from humancal.mocap.asf_amc import _amc_columns, _amc_header, _amc_values_careful, _amc_values_fast
    from humancal.mocap.reading import read_text_lines

    rng = np.random.default_rng(1)
    frames = [(" ".join(f"{v:.5f}" for v in rng.normal(size=6)), f"{rng.normal():.5f}",
               " ".join(f"{v:.5f}" for v in rng.normal(size=2))) for _ in range(7)]
    path = write(tmp_path, "fast.amc", amc_text(frames))
    lines = read_text_lines(path)
    columns, n_cols = _amc_columns(skeleton)
    first, degrees = _amc_header(path, lines, True)
    fast = _amc_values_fast(lines, first, columns, n_cols)
    assert fast is not None and fast.shape == (7, 9) and degrees
    np.testing.assert_array_equal(fast, _amc_values_careful(path, lines, first, columns, n_cols, "99.asf"))
    # bones listed in another order in one frame: still valid AMC, read by the careful path
    swapped = amc_text(frames).replace("thigh " + frames[3][1] + "\r\nshin " + frames[3][2],
                                       "shin " + frames[3][2] + "\r\nthigh " + frames[3][1])
    clip = read_amc(write(tmp_path, "swapped.amc", swapped), skeleton, floor_percentile=None)
    reference = read_amc(path, skeleton, floor_percentile=None)
    np.testing.assert_array_equal(clip.positions_world_m, reference.positions_world_m)


def test_amc_not_a_number(tmp_path, skeleton):
    err = amc_error(tmp_path, skeleton, amc_text([("0 0 0 0 0 0", "0", "0 0"), ("0 0 0 0 0 0", "0", "0 abc")]))
    assert err.line == 8 and "non-number 'abc' for shin" in str(err)
