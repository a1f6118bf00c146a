"""identity_confusion: detections per (true person, estimated id), what merged and what split."""

import pandas as pd

from evaluation.association_metrics import identity_confusion


def test_confusion_counts_merges_splits_and_false_positives():
    truth = pd.DataFrame({"sequence": "s", "frame": [0, 0, 0, 0, 1, 1, 1, 1],
                          "view": [0, 1, 2, 0, 0, 1, 2, 1], "det_id": [0, 0, 0, 1, 0, 0, 0, 1],
                          "person_id": [0, 0, 0, -1, 0, 0, 1, -1]})
    # person 0 split over ids 0 (3) and 1 (2); id 1 also holds person 1 (a merge); one false positive kept as id 2
    estimated = truth.assign(person_id=[0, 0, 1, 2, 0, 1, 1, -1])
    confusion = identity_confusion(estimated, truth)
    assert list(confusion.columns) == ["true", "est", "detections"]
    counts = {(t, e): n for t, e, n in confusion.itertuples(index=False)}
    assert counts == {(0, 0): 3, (0, 1): 2, (1, 1): 1, (-1, 2): 1, (-1, -1): 1}
    assert confusion["detections"].is_monotonic_decreasing and confusion["detections"].sum() == len(truth)
