"""Re-attaching a fragment in place of a weaker branch, through an alternative PAF link.

The greedy assembly decides each limb on its PAF score alone. When a limb picks a spurious candidate (a weak
knee peak on the thigh, say), the person gets a dead-end branch and the true joint with everything below it is
left as a fragment. The fragment is re-attached when the person's parent joint also has a PAF link to the
fragment's root and the fragment carries more evidence than the branch it replaces: more trunk and limb joints
(face and foot points do not count), and more candidate score plus linking PAF score. The replaced branch becomes
a person of its own (usually dropped as too small).
"""

from __future__ import annotations

import numpy as np

from humancal.grouping.candidates import CandidateFrame

__all__ = ["Tree", "reattach_fragments"]


class Tree:
    """Parent and subtree of every joint type of a limb tree.

    Args:
        num_joints: number of joint types.
        tree_limbs: the limbs of a spanning tree, as (joint a, joint b) pairs.
        root: the root joint.

    Raises:
        ValueError: the limbs do not form a spanning tree.
    """

    def __init__(self, num_joints: int, tree_limbs: tuple[tuple[int, int], ...], root: int) -> None:
        neighbours: list[list[int]] = [[] for _ in range(num_joints)]
        for a, b in tree_limbs:
            neighbours[a].append(b)
            neighbours[b].append(a)
        self.parent = np.full(num_joints, -1)
        self.depth = np.full(num_joints, -1)
        self.depth[root] = 0
        queue = [root]
        for j in queue:
            for n in neighbours[j]:
                if self.depth[n] < 0:
                    self.depth[n], self.parent[n] = self.depth[j] + 1, j
                    queue.append(n)
        if len(queue) != num_joints or len(tree_limbs) != num_joints - 1:
            raise ValueError(f"the {len(tree_limbs)} tree limbs do not span the {num_joints} joints as a tree")
        # subtree[j, k]: joint k lies in the subtree rooted at j.
        self.subtree = np.eye(num_joints, dtype=bool)
        for j in sorted(range(num_joints), key=lambda j: -self.depth[j]):
            if self.parent[j] >= 0:
                self.subtree[self.parent[j]] |= self.subtree[j]


def reattach_fragments(
    frame: CandidateFrame, people: list[np.ndarray], tree: Tree, min_paf_score: float, major: np.ndarray
) -> list[np.ndarray]:
    """Replace weaker branches of people by fragments linked to the same parent joint.

    Args:
        frame: the candidates the people index into.
        people: per person (joint,) candidate index, -1 where none.
        tree: the limb tree (parents and subtrees).
        min_paf_score: the alternative link must have a PAF score above this.
        major: (joint,) bool, the joints counted when comparing a fragment with the branch it would replace (the
            trunk and limb joints; face and foot points are too easily missed to decide).

    Returns:
        The people after re-attaching (new arrays; the input is not modified).
    """
    limb_of = {}
    for k, (a, b) in enumerate(frame.limbs):
        limb_of[(a, b)] = (k, False)
        limb_of[(b, a)] = (k, True)
    people = [p.copy() for p in people]
    for _ in range(len(people)):
        move = _best_move(frame, people, tree, limb_of, min_paf_score, major)
        if move is None:
            return people
        f, h = move
        frag, host = people[f], people[h]
        root = _root(frag, tree)
        branch = tree.subtree[root]
        displaced = np.where(branch, host, -1)
        people[h] = np.where(branch, frag, host)
        people[f] = displaced
        people = [p for p in people if (p >= 0).any()]
    return people


def _root(person: np.ndarray, tree: Tree) -> int:
    joints = np.flatnonzero(person >= 0)
    return int(joints[np.argmin(tree.depth[joints])])


def _link(frame: CandidateFrame, limb_of: dict, parent: int, child: int, i: int, j: int) -> float:
    if (parent, child) not in limb_of:
        return 0.0
    k, flipped = limb_of[(parent, child)]
    return float(frame.paf[k][j, i] if flipped else frame.paf[k][i, j])


def _evidence(frame: CandidateFrame, person: np.ndarray) -> float:
    return float(sum(frame.score[j][person[j]] for j in np.flatnonzero(person >= 0)))


def _best_move(
    frame: CandidateFrame, people: list[np.ndarray], tree: Tree, limb_of: dict, min_paf_score: float, major: np.ndarray
) -> tuple[int, int] | None:
    best, best_gain = None, 0.0
    for f, frag in enumerate(people):
        root = _root(frag, tree)
        parent = int(tree.parent[root])
        branch = tree.subtree[root]
        if parent < 0 or ((frag >= 0) & ~branch).any():
            continue
        n_frag = int(((frag >= 0) & major).sum())
        for h, host in enumerate(people):
            if h == f or host[parent] < 0:
                continue
            link = _link(frame, limb_of, parent, root, host[parent], frag[root])
            if link <= min_paf_score:
                continue
            displaced = np.where(branch, host, -1)
            if int(((displaced >= 0) & major).sum()) >= n_frag:
                continue
            old_link = _link(frame, limb_of, parent, root, host[parent], host[root]) if host[root] >= 0 else 0.0
            gain = _evidence(frame, frag) + link - _evidence(frame, displaced) - old_link
            if gain > best_gain:
                best, best_gain = (f, h), gain
    return best
