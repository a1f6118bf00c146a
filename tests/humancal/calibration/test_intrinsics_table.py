"""The intrinsics table round trip."""

import numpy as np
import pytest

from humancal.calibration import IntrinsicsConfig, estimate_intrinsics, intrinsics_from_table, intrinsics_to_table
from humancal.tables.schemas import validate_table


def test_intrinsics_round_trip_through_the_table(ring_scene, ring_stand_in):
    sizes = [(int(r.width_px), int(r.height_px)) for r in ring_scene.cameras.sort_values("view").itertuples()]
    estimates = estimate_intrinsics(ring_stand_in.detections, ring_stand_in.lifted, sizes,
                                    IntrinsicsConfig(missing_upright="defer"))
    table = validate_table(intrinsics_to_table("ring", estimates), "intrinsics")
    back = intrinsics_from_table(table.iloc[::-1])
    for a, b in zip(estimates, back):
        np.testing.assert_allclose(a.K, b.K)
        np.testing.assert_allclose(a.up_cam, b.up_cam)
        assert (a.view, a.status, a.num_inliers, a.width_px) == (b.view, b.status, b.num_inliers, b.width_px)
        assert a.camera_height_m == pytest.approx(b.camera_height_m)
    with pytest.raises(ValueError, match="0..V-1"):
        intrinsics_from_table(table.iloc[1:])
