"""BVH reader on hand-written files whose forward kinematics is worked out by hand."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from humancal.mocap import MocapFormatError, bvh_forward_kinematics, parse_bvh, read_bvh

# A hip -> knee -> ankle chain (Y up, centimetres) with an End Site at the toe; frame lines start at line 24.
CHAIN_HEADER = """HIERARCHY
ROOT hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT knee
  {
    OFFSET 0 -10 0
    CHANNELS 3 {order}
    JOINT ankle
    {
      OFFSET 0 -10 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 0 5
      }
    }
  }
}
"""


def chain_text(order: str, frames: list[str], frame_time: str = "0.04") -> str:
    header = CHAIN_HEADER.replace("{order}", order)
    return header + f"MOTION\nFrames: {len(frames)}\nFrame Time: {frame_time}\n" + "\n".join(frames) + "\n"


def write(tmp_path: Path, text: str, name: str = "07_03.bvh", compress: bool = False) -> Path:
    path = tmp_path / (name + (".gz" if compress else ""))
    data = text.encode()
    path.write_bytes(gzip.compress(data) if compress else data)
    return path


ZXY = "Zrotation Xrotation Yrotation"
XYZ = "Xrotation Yrotation Zrotation"
REST = "0 0 0 0 0 0 0 0 0 0 0 0"


def test_parse_hierarchy_channels_and_columns(tmp_path):
    motion = parse_bvh(write(tmp_path, chain_text(ZXY, [REST, REST])))
    assert [j.name for j in motion.joints] == ["hips", "knee", "ankle", "ankle_end"]
    assert [j.parent for j in motion.joints] == [-1, 0, 1, 2]
    assert [j.first_column for j in motion.joints] == [0, 6, 9, 12]
    assert motion.joints[1].channels == ("Zrotation", "Xrotation", "Yrotation")
    assert motion.joints[3].is_end_site and motion.joints[3].channels == ()
    assert motion.values.shape == (2, 12)
    assert motion.frame_time_s == pytest.approx(0.04)
    assert motion.fps == 25.0


def test_fk_translation_and_single_rotation_by_hand(tmp_path):
    # Root at (1, 2, 3); knee turned +90 deg about z: its child offset (0, -10, 0) becomes (10, 0, 0).
    frame = "1 2 3 0 0 0 90 0 0 0 0 0"
    pos = bvh_forward_kinematics(parse_bvh(write(tmp_path, chain_text(ZXY, [frame]))))[0]
    np.testing.assert_allclose(pos[0], [1, 2, 3], atol=1e-12)
    np.testing.assert_allclose(pos[1], [1, -8, 3], atol=1e-12)
    np.testing.assert_allclose(pos[2], [11, -8, 3], atol=1e-12)
    np.testing.assert_allclose(pos[3], [11, -8, 8], atol=1e-12)  # the toe keeps pointing +z: Rz leaves z alone


def test_rotation_order_zxy_differs_from_xyz_as_computed_by_hand(tmp_path):
    # Knee rotation z = 90, x = 90, y = 0, applied to the ankle offset v = (0, -10, 0):
    #   ZXY channels: R = Rz(90) Rx(90) -> Rx(90) v = (0, 0, -10), then Rz(90) -> (0, 0, -10)
    #   XYZ channels: R = Rx(90) Rz(90) -> Rz(90) v = (10, 0, 0), then Rx(90) -> (10, 0, 0)
    # (an extrinsic reading of ZXY, Ry Rx Rz, would also give (10, 0, 0), so this pins intrinsic order)
    zxy = bvh_forward_kinematics(parse_bvh(write(tmp_path, chain_text(ZXY, ["0 0 0 0 0 0 90 90 0 0 0 0"]))))[0]
    xyz = bvh_forward_kinematics(
        parse_bvh(write(tmp_path, chain_text(XYZ, ["0 0 0 0 0 0 90 0 90 0 0 0"]), name="b.bvh"))
    )[0]
    np.testing.assert_allclose(zxy[2] - zxy[1], [0, 0, -10], atol=1e-12)
    np.testing.assert_allclose(xyz[2] - xyz[1], [10, 0, 0], atol=1e-12)


def test_rotations_compose_down_the_chain(tmp_path):
    # Root yawed +90 deg about y maps the toe offset (0, 0, 5) to (5, 0, 0); the chain hangs straight down.
    frame = "0 20 0 0 0 90 0 0 0 0 0 0"
    pos = bvh_forward_kinematics(parse_bvh(write(tmp_path, chain_text(ZXY, [frame]))))[0]
    np.testing.assert_allclose(pos[3], [5, 0, 0], atol=1e-12)


def test_read_bvh_converts_units_axes_floor_and_drops_first_frame(tmp_path):
    tpose = "50 50 50 30 40 50 60 70 80 10 20 30"  # junk "T-pose" frame: must not reach the output
    frames = [tpose, "1 20 3 0 0 0 90 0 0 0 0 0", "1 30 3 0 0 0 90 0 0 0 0 0"]
    clip = read_bvh(write(tmp_path, chain_text(ZXY, frames), compress=True), drop_leading_frames=1,
                    include_end_sites=True)
    assert clip.frames == 2 and clip.fps == 25.0 and clip.duration_s == pytest.approx(0.08)
    assert clip.name == "07_03" and clip.subject == "07"
    assert clip.joint_names == ("hips", "knee", "ankle", "ankle_end")
    assert clip.parents == (-1, 0, 1, 2)
    # file (x, y, z) cm -> world (x, -z, y) m; frame 1 file positions: hips (1,20,3), knee (1,10,3),
    # ankle (11,10,3), toe (11,10,8). Lowest node per frame: toe/ankle at file y = 10, then 20;
    # 5th percentile of (0.10, 0.20) m = 0.105 m becomes the floor.
    expected = np.array([[1, -3, 20], [1, -3, 10], [11, -3, 10], [11, -8, 10]]) * 0.01
    expected[:, 2] -= 0.105
    np.testing.assert_allclose(clip.positions_world_m[0], expected, atol=1e-12)
    np.testing.assert_allclose(clip.positions_world_m[1, :, 2] - clip.positions_world_m[0, :, 2], 0.10, atol=1e-12)


def test_read_bvh_options(tmp_path):
    path = write(tmp_path, chain_text(ZXY, ["1 20 3 0 0 0 0 0 0 0 0 0"]))
    clip = read_bvh(path, drop_leading_frames=0, metres_per_unit=1.0, up_axis="z", floor_percentile=None)
    assert clip.joint_names == ("hips", "knee", "ankle")  # End Sites left out by default
    np.testing.assert_allclose(clip.positions_world_m[0], [[1, 20, 3], [1, 10, 3], [1, 0, 3]], atol=1e-12)
    with pytest.raises(MocapFormatError, match="nothing left after dropping 8 leading frame"):
        read_bvh(path)
    for bad in (True, -1, 1.5):
        with pytest.raises(ValueError, match="drop_leading_frames must be a count"):
            read_bvh(path, drop_leading_frames=bad)
    with pytest.raises(ValueError, match="up_axis"):
        read_bvh(path, up_axis="x")


def test_position_channels_on_a_child_replace_its_offset(tmp_path):
    text = chain_text(ZXY, [REST]).replace("CHANNELS 3 Zrotation Xrotation Yrotation\n    JOINT ankle",
                                           "CHANNELS 4 Yposition Zrotation Xrotation Yrotation\n    JOINT ankle")
    text = text.replace("\n" + REST + "\n", "\n0 0 0 0 0 0 -7 0 0 0 0 0 0\n")
    pos = bvh_forward_kinematics(parse_bvh(write(tmp_path, text)))[0]
    np.testing.assert_allclose(pos[1], [0, -7, 0], atol=1e-12)


# ---- bad inputs: each error names the file, the line and what was expected -----------------------


def error_of(tmp_path: Path, text: str, compress: bool = False) -> MocapFormatError:
    path = write(tmp_path, text, compress=compress)
    with pytest.raises(MocapFormatError) as info:
        read_bvh(path, drop_leading_frames=0)
    assert str(path) in str(info.value)
    return info.value


def test_truncated_file(tmp_path):
    err = error_of(tmp_path, chain_text(ZXY, [REST, REST, REST]).replace("Frames: 3", "Frames: 5"))
    assert "truncated" in str(err) and "expected 5" in str(err) and err.line == 26


def test_truncated_gzip(tmp_path):
    path = tmp_path / "x.bvh.gz"
    path.write_bytes(gzip.compress(chain_text(ZXY, [REST] * 50).encode())[:-40])
    with pytest.raises(MocapFormatError, match="truncated gzip"):
        read_bvh(path)


def test_hierarchy_cut_short(tmp_path):
    text = "\n".join(chain_text(ZXY, [REST]).splitlines()[:9]) + "\nMOTION\nFrames: 1\nFrame Time: 0.1\n" + REST
    err = error_of(tmp_path, text)
    assert "HIERARCHY ends early" in str(err) and err.line == 9


def test_unknown_channel(tmp_path):
    err = error_of(tmp_path, chain_text("Zrotation Xrotation Wrotation", [REST]))
    assert err.line == 9 and "unknown channel 'Wrotation' of joint 'knee'" in str(err)
    assert "Xposition" in str(err)  # lists what would have been accepted


def test_frame_with_wrong_number_of_values(tmp_path):
    err = error_of(tmp_path, chain_text(ZXY, [REST, "0 0 0 0 0 0 0 0 0 0 0", REST]))
    assert err.line == 25 and "frame 2 has 11 values; expected 12" in str(err)


def test_extra_frame_lines(tmp_path):
    err = error_of(tmp_path, chain_text(ZXY, [REST, REST]).replace("Frames: 2", "Frames: 1"))
    assert err.line == 25 and "more frame lines" in str(err)


def test_missing_motion_section(tmp_path):
    err = error_of(tmp_path, CHAIN_HEADER.replace("{order}", ZXY))
    assert "no MOTION section" in str(err)


def test_nan_value(tmp_path):
    err = error_of(tmp_path, chain_text(ZXY, [REST, "0 0 0 0 nan 0 0 0 0 0 0 0"]), compress=True)
    assert err.line == 25 and "non-finite value 'nan' in column 5" in str(err)


def test_not_a_number(tmp_path):
    err = error_of(tmp_path, chain_text(ZXY, ["0 0 0 0 0 x 0 0 0 0 0 0"]))
    assert err.line == 24 and "expected a number in column 6, found 'x'" in str(err)


def test_bad_frame_time(tmp_path):
    err = error_of(tmp_path, chain_text(ZXY, [REST], frame_time="0"))
    assert err.line == 23 and "Frame Time" in str(err)


def test_bad_offset(tmp_path):
    err = error_of(tmp_path, chain_text(ZXY, [REST]).replace("OFFSET 0 -10 0", "OFFSET 0 abc 0", 1))
    assert err.line == 8 and "expected OFFSET y (a number), found 'abc'" in str(err)
