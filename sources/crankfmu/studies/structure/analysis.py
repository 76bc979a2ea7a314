"""Structural analysis: counting formulas and the rank of the loop-closure (constraint) Jacobian.

Screw-theory count (docs/structure.md, section 3):

* Every joint freedom is a unit twist $ = (omega; v) (v: velocity of the point at the origin)
  of the joint's second link relative to its first, in the given assembled configuration.
* A spanning tree of the link graph, rooted at the frame, gives each link's absolute twist as a
  sum of joint twists; every joint not in the tree closes one independent loop (k = p - n), and
  the closure "twist of b - twist of a - $_j = 0" gives 6 rows. K is the 6k x f matrix.
* rank r of K: dof_total = f - r (first-order mobility), q = 6k - r (redundant constraints).
  The left null space of K holds the redundant constraints as wrenches (force; moment): a pure
  couple about an axis blocks "rotation about" it, a force along a line blocks "translation
  along" it. They are reported per loop where they belong to one loop.
* Main mobility = rank of the map from the null space of K to the declared output
  coordinates (`outputs`); local mobilities = dof_total - main: motions of the joints that
  leave every output coordinate at rest (an RSSR rod spinning about its S-S line).

Counting formulas: Chebyshev W = 3n - 2p1 - p2 (planar mechanisms only), Malyshev
W = 6n - 5p1 - 4p2 - 3p3 - 2p4 - p5 and q = W - 6n + 5p1 + 4p2 + 3p3 + 2p4 + p5, Ozol
q = W + 6k - f; p_j counts joints with j freedoms. The q formulas need W: they are evaluated
with W = the main mobility found by the rank analysis (the designer's W) and, as a check, with
W = dof_total (then they equal the rank count identically).
"""
from __future__ import annotations

import json
from collections import Counter
from dataclasses import asdict, dataclass, field

import numpy as np

from .description import FRAME, Mechanism

AXES = {"x": np.array([1.0, 0, 0]), "y": np.array([0, 1.0, 0]), "z": np.array([0, 0, 1.0])}


@dataclass
class StructureResult:
    name: str
    source: str
    n: int
    p: int
    k: int
    f: int
    p_by_freedom: dict
    W_chebyshev: int | None
    W_malyshev: int
    W_formulas: int
    q_malyshev: int
    q_ozol: int
    q_formulas_total: int
    dof_total: int
    mobility: int
    local_mobilities: dict
    redundant: dict
    rank: int
    jacobian_shape: tuple
    singular_values: list
    outputs: list
    planar: dict | None = None
    loops: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["jacobian_shape"] = list(self.jacobian_shape)
        d["p_by_freedom"] = {str(k): v for k, v in self.p_by_freedom.items()}
        return d

    def __getitem__(self, key):
        return self.to_dict()[key]

    def keys(self):
        return self.to_dict().keys()

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, ensure_ascii=False)


# -- linear algebra helpers -----------------------------------------------------------------
def _svd_rank(a: np.ndarray, tol: float):
    """(rank, U, s, Vt) with singular values below tol * max(1, s_max) counted as zero."""
    if a.size == 0:
        return 0, np.eye(a.shape[0]), np.zeros(0), np.eye(a.shape[1])
    u, s, vt = np.linalg.svd(a, full_matrices=True)
    cut = tol * max(1.0, float(s[0]) if s.size else 1.0)
    return int(np.sum(s > cut)), u, s, vt


def _null(a: np.ndarray, tol: float) -> np.ndarray:
    if a.shape[0] == 0:
        return np.eye(a.shape[1])
    r, _, _, vt = _svd_rank(a, tol)
    return vt[r:].T


def _orth(a: np.ndarray, tol: float) -> np.ndarray:
    if a.size == 0:
        return np.zeros((a.shape[0], 0))
    r, u, _, _ = _svd_rank(a, tol)
    return u[:, :r]


def _nice_basis(q: np.ndarray, tol: float = 1e-6) -> list[np.ndarray]:
    """Orthonormal basis of span(q) in R^3 preferring the coordinate axes."""
    m = q.shape[1]
    chosen: list[np.ndarray] = []
    for e in AXES.values():
        if len(chosen) == m:
            break
        if np.linalg.norm(e - q @ (q.T @ e)) < tol and all(abs(e @ c) < tol for c in chosen):
            chosen.append(e.copy())
    for col in q.T:
        if len(chosen) == m:
            break
        v = col - sum((col @ c) * c for c in chosen) if chosen else col.copy()
        if np.linalg.norm(v) > 1e-6:
            v = v / np.linalg.norm(v)
            if v[np.argmax(np.abs(v))] < 0:
                v = -v
            chosen.append(v)
    return chosen


def _dir_name(d: np.ndarray) -> str:
    for name, e in AXES.items():
        if np.linalg.norm(d - e) < 1e-6:
            return name
        if np.linalg.norm(d + e) < 1e-6:
            return f"-{name}"
    return "({:.4g}, {:.4g}, {:.4g})".format(*(0.0 if abs(c) < 5e-13 else c for c in d))


def _pt(p: np.ndarray) -> str:
    return "({:.4g}, {:.4g}, {:.4g})".format(*(0.0 if abs(c) < 5e-12 else c for c in p))


# -- the analysis -----------------------------------------------------------------------------
class _Model:
    """Conditioned twists, the spanning tree and the loop-closure matrix of a mechanism."""

    def __init__(self, mech: Mechanism):
        self.mech = mech
        pts = np.array([j.point for j in mech.joints], dtype=float)
        self.centre = pts.mean(axis=0)
        spread = float(np.max(np.linalg.norm(pts - self.centre, axis=1)))
        self.scale = spread if spread > 1e-12 else 1.0
        self.cols = []            # (joint index, freedom index) per column
        self.twists = []          # 6 x f_j per joint, conditioned coordinates
        start = 0
        self.col_of = []
        for ji, j in enumerate(mech.joints):
            p = (np.array(j.point) - self.centre) / self.scale
            t = []
            for fr in j.freedoms:
                d = np.array(fr.direction)
                t.append(np.concatenate([d, np.cross(p, d)]) if fr.kind == "r"
                         else np.concatenate([np.zeros(3), d]))
            self.twists.append(np.array(t).T)
            self.col_of.append(slice(start, start + j.f))
            self.cols += [(ji, fi) for fi in range(j.f)]
            start += j.f
        self.f = start
        self._tree()

    def _tree(self):
        mech = self.mech
        links = [FRAME] + list(mech.links)
        link_T = {FRAME: np.zeros((6, self.f))}
        parent_joint = {FRAME: None}
        depth = {FRAME: 0}
        tree_joints = set()
        queue = [FRAME]
        while queue:
            cur = queue.pop(0)
            for ji, j in enumerate(mech.joints):
                a, b = j.between
                if cur not in (a, b):
                    continue
                other = b if cur == a else a
                if other in link_T:
                    continue
                sign = 1.0 if cur == a else -1.0
                T = link_T[cur].copy()
                T[:, self.col_of[ji]] += sign * self.twists[ji]
                link_T[other] = T
                parent_joint[other] = (ji, cur)
                depth[other] = depth[cur] + 1
                tree_joints.add(ji)
                queue.append(other)
        assert set(link_T) == set(links)
        self.link_T = link_T
        self.parent_joint = parent_joint
        self.depth = depth
        self.chords = [ji for ji in range(len(mech.joints)) if ji not in tree_joints]
        rows, loops = [], []
        for ji in self.chords:
            a, b = mech.joints[ji].between
            E = np.zeros((6, self.f))
            E[:, self.col_of[ji]] = self.twists[ji]
            rows.append(link_T[b] - link_T[a] - E)
            loops.append(self._loop_joints(ji))
        self.K = np.vstack(rows) if rows else np.zeros((0, self.f))
        self.loops = loops

    def _path_to_root(self, link):
        out = []
        while self.parent_joint[link] is not None:
            ji, par = self.parent_joint[link]
            out.append((ji, link))
            link = par
        return out

    def _loop_joints(self, chord):
        a, b = self.mech.joints[chord].between
        pa, pb = self._path_to_root(a), self._path_to_root(b)
        ja, jb = [x[0] for x in pa], [x[0] for x in pb]
        common = set(ja) & set(jb)
        ja = [x for x in ja if x not in common]
        jb = [x for x in jb if x not in common]
        return list(reversed(ja)) + [chord] + jb

    def physical_point(self, p_scaled):
        return self.centre + self.scale * p_scaled


def analyse(mech: Mechanism) -> StructureResult:
    """Structural analysis of a validated mechanism (see the module docstring)."""
    model = _Model(mech)
    tol = mech.rank_tolerance
    n, p, f = mech.n, mech.p, model.f
    k = len(model.chords)
    K = model.K
    rank, U, s, Vt = _svd_rank(K, tol)
    dof_total = f - rank
    q = 6 * k - rank
    N = Vt[rank:].T if f else np.zeros((0, 0))

    # main and local mobilities
    O = _output_rows(mech, model)
    ON = O @ N if N.size else np.zeros((O.shape[0], 0))
    main, _, _, _ = _svd_rank(ON, tol) if ON.size else (0, None, None, None)
    local_basis = N @ _null(ON, tol) if dof_total else np.zeros((f, 0))
    local_names = _describe_locals(mech, model, local_basis, tol)

    # redundant constraints
    Bl = U[:, rank:] if q else np.zeros((6 * k, 0))
    redundant_names = _describe_redundant(mech, model, Bl, tol)

    # counting formulas
    p_by = Counter(j.f for j in mech.joints)
    constraints = sum((6 - j.f) for j in mech.joints)
    W_mal = 6 * n - constraints
    q_mal = main - 6 * n + constraints
    q_ozol = main + 6 * k - f
    q_total = dof_total - 6 * n + constraints

    planar = _planar(mech, model, N, main, tol)
    notes = _notes(mech, main, dof_total, q, q_mal, s, rank, tol)
    loops = [" - ".join(mech.joints[j].name for j in lp) for lp in model.loops]
    return StructureResult(
        name=mech.name, source=mech.source, n=n, p=p, k=k, f=f,
        p_by_freedom={j: p_by[j] for j in sorted(p_by)},
        W_chebyshev=planar["W_chebyshev"] if planar else None,
        W_malyshev=W_mal, W_formulas=main, q_malyshev=q_mal, q_ozol=q_ozol,
        q_formulas_total=q_total, dof_total=dof_total, mobility=main,
        local_mobilities={"count": dof_total - main, "directions": local_names},
        redundant={"count": q, "directions": redundant_names},
        rank=rank, jacobian_shape=(6 * k, f),
        singular_values=[float(x) for x in s],
        outputs=[str(o) for o in mech.outputs], planar=planar, loops=loops, notes=notes)


def _output_rows(mech: Mechanism, model: _Model) -> np.ndarray:
    rows = []
    for o in mech.outputs:
        T = model.link_T[o.link]
        if o.coordinate is None:
            rows.append(T)
            continue
        kind, ax = o.coordinate[0], "xyz".index(o.coordinate[1])
        if kind == "r":
            rows.append(T[ax:ax + 1])
        else:
            pref = (mech.reference_point(o.link) - model.centre) / model.scale
            # v(p) = v0 + omega x p; component ax of omega x p is linear in omega rows
            e = np.zeros(3)
            e[ax] = 1.0
            w_coef = np.cross(pref, e)  # e . (omega x p) = omega . (p x e)
            rows.append((T[3 + ax] + w_coef @ T[0:3])[None, :])
    return np.vstack(rows) if rows else np.zeros((0, model.f))


def _line_on_joints(mech, link, point, direction, tol=1e-6):
    on = []
    for j in mech.joints:
        if link in j.between:
            d = np.array(j.point) - point
            if np.linalg.norm(np.cross(d, direction)) < tol * max(1.0, np.linalg.norm(d)):
                on.append(j.name)
    return on


def _describe_link_motion(mech, model, link, twist, tol):
    w, v = twist[:3], twist[3:]
    nw = np.linalg.norm(w)
    if nw > tol:
        d = w / nw
        h = float(d @ v) / nw
        p_scaled = np.cross(w, v) / nw ** 2
        pt = model.physical_point(p_scaled)
        if d[np.argmax(np.abs(d))] < 0:
            d = -d
        on = _line_on_joints(mech, link, pt, d)
        where = (f"the line {'–'.join(on)}" if len(on) >= 2 else
                 f"the axis {_dir_name(d)} through {_pt(pt)}"
                 + (f" (joint {on[0]})" if on else ""))
        text = f"{link} rotates about {where}"
        if abs(h) > 1e-6:
            text += f" with pitch {h * model.scale:.4g} m/rad"
        return text
    nv = np.linalg.norm(v)
    return f"{link} translates along {_dir_name(v / nv)}"


def _describe_locals(mech, model, Z, tol):
    """Names for a basis of the local mobilities Z (f x l, joint velocities).

    Motions that move a single link come first (an RSSR rod spinning); the rest are named by
    the motion of one describing link (an output link if it moves), choosing axis-aligned
    rotations about its reference point and translations where the space allows.
    """
    if Z.shape[1] == 0:
        return []
    links = list(mech.links)
    names, found = [], []
    for ln in links:
        others = [model.link_T[o] @ Z for o in links if o != ln]
        beta = _null(np.vstack(others), tol) if others else np.eye(Z.shape[1])
        if beta.shape[1] == 0:
            continue
        Zs = _complement(Z @ beta, found, tol)
        for vec in _elementary(mech, model, ln, Zs, tol):
            found.append(vec)
            names.append(_describe_link_motion(mech, model, ln, model.link_T[ln] @ vec, tol))
    rest = _complement(Z, found, tol)
    while rest.shape[1]:
        ranks = []
        for ln in links:
            rk = np.linalg.matrix_rank(_ref_twist(mech, model, ln) @ rest, tol=1e-7)
            ranks.append((rk, any(o.link == ln for o in mech.outputs), ln))
        _, _, ln = max(ranks)
        vecs = _elementary(mech, model, ln, rest, tol)
        if not vecs:  # cannot happen for a non-trivial motion; guard against an endless loop
            vecs = list(rest.T)
        for vec in vecs:
            found.append(vec)
            movers = [o for o in links if o != ln and np.linalg.norm(model.link_T[o] @ vec)
                      > 1e-7 * max(1.0, np.linalg.norm(model.link_T[ln] @ vec))]
            text = _describe_link_motion(mech, model, ln, model.link_T[ln] @ vec, tol)
            if movers:
                text += " (" + ", ".join(movers) + " follow)"
            names.append(text)
        rest = _complement(Z, found, tol)
    return names


def _ref_twist(mech, model, link):
    """6 x f map from joint velocities to the link's twist at its reference point."""
    T = model.link_T[link]
    pref = (mech.reference_point(link) - model.centre) / model.scale
    skew = np.array([[0, -pref[2], pref[1]], [pref[2], 0, -pref[0]], [-pref[1], pref[0], 0]])
    # v_ref = v0 + omega x pref = v0 - pref x omega
    return np.vstack([T[:3], T[3:] - skew @ T[:3]])


def _elementary(mech, model, link, Zs, tol):
    """Basis of span(Zs) whose motions of `link` are elementary where possible.

    Elementary: rotation about x, y or z through the link's reference point, or translation
    along x, y or z. Motions of span(Zs) that do not move `link` are left out.
    """
    if Zs.shape[1] == 0:
        return []
    A = _ref_twist(mech, model, link) @ Zs
    r, u, s, vt = _svd_rank(A, 1e-7)
    if r == 0:
        return []
    rng = u[:, :r]
    chosen = []
    for i in range(6):
        e = np.zeros(6)
        e[i] = 1.0
        if np.linalg.norm(e - rng @ (rng.T @ e)) < 1e-6 and \
                np.linalg.matrix_rank(np.column_stack(chosen + [e]), tol=1e-6) > len(chosen):
            chosen.append(e)
    for col in rng.T:
        if len(chosen) == r:
            break
        M = np.column_stack(chosen) if chosen else np.zeros((6, 0))
        v = col - M @ np.linalg.lstsq(M, col, rcond=None)[0] if chosen else col
        if np.linalg.norm(v) > 1e-6:
            chosen.append(v / np.linalg.norm(v))
    out = []
    for e in chosen:
        c, *_ = np.linalg.lstsq(A, e, rcond=None)
        vec = Zs @ c
        out.append(vec / np.linalg.norm(vec))
    return out


def _complement(Z, found, tol):
    """Orthonormal basis of span(Z) orthogonal to the vectors in `found`."""
    basis = _orth(Z, tol)
    if not found:
        return basis
    F = _orth(np.column_stack(found), tol)
    R = basis - F @ (F.T @ basis)
    return _orth(R, 1e-6)


def _describe_wrench_space(mech, model, Y, loop_index, tol):
    """Names for the wrenches spanned by Y (6 x m, rows: moment at centre; force)."""
    M, F = Y[:3], Y[3:]
    names = []
    coef = _null(F, 1e-7)                      # combinations with no force: pure couples
    couples = _orth(M @ coef, 1e-7) if coef.shape[1] else np.zeros((3, 0))
    for d in _nice_basis(couples):
        names.append(f"rotation about {_dir_name(d)}")
    force_dirs = _orth(F, 1e-7)
    for e in _nice_basis(force_dirs):
        alpha, *_ = np.linalg.lstsq(F, e, rcond=None)
        m = M @ alpha
        if couples.shape[1]:
            m = m - couples @ (couples.T @ m)
        h = float(e @ m)
        pt = model.physical_point(np.cross(e, m))
        text = f"translation along {_dir_name(e)} (line through {_pt(pt)})"
        if abs(h) > 1e-6:
            text = (f"screw along {_dir_name(e)} (line through {_pt(pt)}, pitch "
                    f"{h * model.scale:.4g} m)")
        else:
            text += _rod_note(mech, model, loop_index, e)
        names.append(text)
    return names


def _rod_note(mech, model, loop_index, e):
    """Which link dimensions a redundant force along e ties together (the dimension chain)."""
    if loop_index is None:
        return ""
    loop = model.loops[loop_index]
    parts, all_parallel = [], True
    for i, ja in enumerate(loop):
        jb = loop[(i + 1) % len(loop)]
        A, B = mech.joints[ja], mech.joints[jb]
        shared = set(A.between) & set(B.between)
        if not shared:
            continue
        link = sorted(shared)[0]
        seg = np.array(B.point) - np.array(A.point)
        along = float(seg @ e)
        if abs(along) <= 1e-9 * model.scale:
            continue
        if np.linalg.norm(np.cross(seg, e)) > 1e-6 * np.linalg.norm(seg):
            all_parallel = False
        parts.append(f"{link} ({A.name}–{B.name})")
    if not parts:
        return ""
    if all_parallel and len(parts) == 2:
        return ": the lengths of " + " and ".join(parts) + " must agree"
    if all_parallel and len(parts) > 2:
        return ": the collinear lengths of " + ", ".join(parts) + " must close"
    return ": dimension chain along it: " + ", ".join(parts)


def _describe_redundant(mech, model, B, tol):
    q = B.shape[1]
    if q == 0:
        return []
    k = len(model.chords)
    names, found = [], []
    for i in range(k):
        other = np.delete(np.arange(6 * k), np.arange(6 * i, 6 * i + 6))
        alpha = _null(B[other], 1e-7) if other.size else np.eye(q)
        if alpha.shape[1] == 0:
            continue
        Y = B[6 * i:6 * i + 6] @ alpha
        prefix = f"loop {i + 1} ({' - '.join(mech.joints[j].name for j in model.loops[i])}): " \
            if k > 1 else ""
        for nm in _describe_wrench_space(mech, model, Y, i, tol):
            names.append(prefix + nm)
        full = np.zeros((6 * k, alpha.shape[1]))
        full[6 * i:6 * i + 6] = Y
        found.extend(full.T)
    rest = _complement(B, found, tol)
    for vec in rest.T:
        parts = []
        for i in range(k):
            blk = vec[6 * i:6 * i + 6]
            if np.linalg.norm(blk) > 1e-6:
                sub = _describe_wrench_space(mech, model, blk[:, None], i, tol)
                parts.append(f"loop {i + 1}: " + ", ".join(sub))
        names.append("coupled over loops: " + "; ".join(parts))
    return names


def _planar(mech, model, N, main, tol):
    """Planar check and Chebyshev's count; None if the mechanism does not move in a plane."""
    normal = None
    motion = [model.link_T[ln] @ N for ln in mech.links] if N.size else []
    cols = np.hstack(motion) if motion else np.zeros((6, 0))
    cols = cols[:, np.linalg.norm(cols, axis=0) > 1e-9] if cols.size else cols
    if cols.shape[1]:
        w = cols[:3]
        big = np.argmax(np.linalg.norm(w, axis=0))
        if np.linalg.norm(w[:, big]) > 1e-9:
            normal = w[:, big] / np.linalg.norm(w[:, big])
        else:  # translations only: the normal of their span
            vs = _orth(cols[3:], 1e-7)
            if vs.shape[1] <= 2:
                normal = np.cross(*vs.T) if vs.shape[1] == 2 else None
    if normal is None:
        rot = [np.array(fr.direction) for j in mech.joints for fr in j.freedoms if fr.kind == "r"]
        if not rot:
            return None
        normal = rot[0]
    normal = normal / np.linalg.norm(normal)
    if normal[np.argmax(np.abs(normal))] < 0:
        normal = -normal
    u = np.cross(normal, [1.0, 0, 0])
    if np.linalg.norm(u) < 0.5:
        u = np.cross(normal, [0, 1.0, 0])
    u /= np.linalg.norm(u)
    w2 = np.cross(normal, u)
    P = np.zeros((6, 3))
    P[:3, 0] = normal
    P[3:, 1] = u
    P[3:, 2] = w2
    if cols.shape[1]:
        resid = cols - P @ (P.T @ cols)
        if np.max(np.linalg.norm(resid, axis=0) / np.linalg.norm(cols, axis=0)) > 1e-6:
            return None
    # planar freedoms of every joint: span(joint twists) ∩ planar subalgebra
    planar_f, planar_twists = [], []
    for ji, j in enumerate(mech.joints):
        J = model.twists[ji]
        nb = _null(np.hstack([J, -P]), 1e-9)
        beta = _orth(nb[J.shape[1]:], 1e-9) if nb.shape[1] else np.zeros((3, 0))
        planar_f.append(beta.shape[1])
        planar_twists.append(beta)
    if mech.joints and not any(planar_f):
        return None
    n = mech.n
    W_cheb = 3 * n - sum(3 - fp for fp in planar_f)
    counts = Counter(planar_f)
    # planar loop-closure matrix (3 rows per loop) from the same tree
    fp_total = sum(planar_f)
    col_of, start = [], 0
    for fp in planar_f:
        col_of.append(slice(start, start + fp))
        start += fp
    link_T = {FRAME: np.zeros((3, fp_total))}
    for ln in sorted(model.depth, key=lambda x: model.depth[x]):
        if ln == FRAME:
            continue
        ji, par = model.parent_joint[ln]
        sign = 1.0 if mech.joints[ji].between[0] == par else -1.0
        T = link_T[par].copy()
        T[:, col_of[ji]] += sign * planar_twists[ji]
        link_T[ln] = T
    rows = []
    for ji in model.chords:
        a, b = mech.joints[ji].between
        E = np.zeros((3, fp_total))
        E[:, col_of[ji]] = planar_twists[ji]
        rows.append(link_T[b] - link_T[a] - E)
    Kp = np.vstack(rows) if rows else np.zeros((0, fp_total))
    rank_p = _svd_rank(Kp, tol)[0] if Kp.size else 0
    k = len(model.chords)
    return {
        "normal": _dir_name(normal),
        "p_planar": {str(c): counts[c] for c in sorted(counts)},
        "W_chebyshev": W_cheb,
        "q_chebyshev": main - W_cheb,
        "rank": rank_p,
        "dof": fp_total - rank_p,
        "q": 3 * k - rank_p,
    }


def _notes(mech, main, dof_total, q, q_mal, s, rank, tol):
    notes = []
    if not mech.outputs_declared:
        notes.append("outputs not declared: the main mobility counts the whole poses of the "
                     "links jointed to the frame (" + ", ".join(str(o) for o in mech.outputs)
                     + ")")
    if rank:
        smallest_kept = float(s[rank - 1])
        if smallest_kept < 1e3 * tol * max(1.0, float(s[0])):
            notes.append(f"near a singular configuration: smallest kept singular value "
                         f"{smallest_kept:.3g}; check the rank at another configuration")
    return notes
