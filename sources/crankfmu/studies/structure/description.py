"""Mechanism description files (TOML): reading and validation.

Format (see docs/structure.md for the full reference)::

    [mechanism]
    name = "stand_drive_p1"
    links = ["crank", "rod2", "stand", "rod4"]     # moving links; "frame" is implicit
    outputs = ["crank.rx", "stand.ty"]             # optional, see below
    description = "free text"                      # optional
    rank_tolerance = 1e-8                          # optional, relative singular-value cut-off

    [[joints]]
    name = "A"
    between = ["crank", "rod2"]     # the freedoms are motions of the 2nd link relative to the 1st
    type = "R"                      # R, P, C, U, S or E ...
    # free = ["rx", "tx", {r = [0, 1, 0]}]   # ... or any set of freed axes instead of `type`
    point = [0.0, 0.15, 0.26]       # geometry in one generic assembled configuration
    axis = [1, 0, 0]
    # axis2 = [0, 0, 1]             # U joints: the second rotation axis (through `point`)

Joint types and their freedoms (unit twists in the file's coordinate frame):
    R  rotation about `axis` through `point`                                  1
    P  translation along `axis` (`point` optional, used in names only)         1
    C  rotation about and translation along `axis` through `point`            2
    U  rotations about `axis` and `axis2`, both through `point`               2
    S  rotations about x, y, z through `point` (`axis` not used)              3
    E  planar pair: rotation about the normal `axis` through `point` and the
       two translations perpendicular to it                                   3
    free = [...]  any set of freed axes: "rx", "ry", "rz" (rotations about the
       file's axes through `point`), "tx", "ty", "tz" (translations), or inline
       tables {r = [x, y, z]} / {t = [x, y, z]} for an arbitrary direction.

`outputs` entries are "link" (the whole pose of the link) or "link.rx" ... "link.tz" (one
coordinate: rotation about / translation along a file axis, translations measured at the
link's reference point = the centroid of the points of its joints). Default: the whole pose
of every link that has a joint with the frame.
"""
from __future__ import annotations

from ...errors import CrankfmuError

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

FRAME = "frame"
JOINT_TYPES = ("R", "P", "C", "U", "S", "E")
AXIS_NAMES = ("rx", "ry", "rz", "tx", "ty", "tz")
MECHANISM_KEYS = ("name", "links", "outputs", "description", "rank_tolerance")
JOINT_KEYS = ("name", "between", "type", "free", "point", "axis", "axis2", "description")
TOP_KEYS = ("mechanism", "joints")
UNIT = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
DEFAULT_RANK_TOLERANCE = 1e-8


class MechanismError(CrankfmuError, ValueError):
    """An invalid mechanism description; names the file, the key and what is allowed."""

    def __init__(self, source: str, key: str, problem: str, allowed: str = ""):
        self.source, self.key, self.problem, self.allowed = source, key, problem, allowed
        text = f"{source}: {key}: {problem}"
        if allowed:
            text += f" (allowed: {allowed})"
        super().__init__(text)


@dataclass(frozen=True)
class Freedom:
    """One freed axis of a joint: kind 'r' (rotation) or 't' (translation) along `direction`."""

    kind: str
    direction: tuple[float, float, float]
    label: str


@dataclass(frozen=True)
class Joint:
    name: str
    between: tuple[str, str]
    kind: str                      # "R", ..., "E" or "free"
    point: tuple[float, float, float]
    freedoms: tuple[Freedom, ...]
    axis: tuple[float, float, float] | None = None
    axis2: tuple[float, float, float] | None = None
    description: str = ""

    @property
    def f(self) -> int:
        """Number of freedoms (the joint is a p_f pair in Malyshev's count)."""
        return len(self.freedoms)

    def twists(self) -> np.ndarray:
        """6 x f matrix of unit twists (omega; v at the origin) of link 2 relative to link 1."""
        p = np.array(self.point, dtype=float)
        cols = []
        for fr in self.freedoms:
            d = np.array(fr.direction, dtype=float)
            if fr.kind == "r":
                cols.append(np.concatenate([d, np.cross(p, d)]))
            else:
                cols.append(np.concatenate([np.zeros(3), d]))
        return np.array(cols, dtype=float).T.reshape(6, len(cols))


@dataclass(frozen=True)
class Output:
    link: str
    coordinate: str | None  # None: the whole pose

    def __str__(self) -> str:
        return self.link if self.coordinate is None else f"{self.link}.{self.coordinate}"


@dataclass
class Mechanism:
    name: str
    links: tuple[str, ...]
    joints: tuple[Joint, ...]
    outputs: tuple[Output, ...]
    source: str = "<memory>"
    description: str = ""
    rank_tolerance: float = DEFAULT_RANK_TOLERANCE
    outputs_declared: bool = False

    @property
    def n(self) -> int:
        return len(self.links)

    @property
    def p(self) -> int:
        return len(self.joints)

    def reference_point(self, link: str) -> np.ndarray:
        pts = [j.point for j in self.joints if link in j.between]
        return np.mean(np.array(pts, dtype=float), axis=0)


# -- reading ---------------------------------------------------------------------------------
def load_mechanism(path) -> Mechanism:
    """Read and validate a mechanism description file; raise MechanismError on any problem."""
    path = Path(path)
    source = str(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise MechanismError(source, "(file)", f"cannot be read: {exc.strerror or exc}") from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        raise MechanismError(source, "(file)", "is not UTF-8 text") from None
    except tomllib.TOMLDecodeError as exc:
        raise MechanismError(source, "(file)", f"is not valid TOML: {exc}") from None
    return mechanism_from_dict(data, source)


def loads_mechanism(text: str, source: str = "<string>") -> Mechanism:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MechanismError(source, "(file)", f"is not valid TOML: {exc}") from None
    return mechanism_from_dict(data, source)


def _unknown_keys(source, where, table, allowed):
    extra = sorted(set(table) - set(allowed))
    if extra:
        raise MechanismError(source, f"{where}{extra[0]}", "unknown key",
                             ", ".join(allowed))


def _vector(source, key, value, *, unit: bool) -> tuple[float, float, float]:
    if (not isinstance(value, list) or len(value) != 3
            or not all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in value)):
        raise MechanismError(source, key, f"{value!r} is not a 3-vector",
                             "a list of three numbers [x, y, z]")
    v = np.array(value, dtype=float)
    if not np.all(np.isfinite(v)):
        raise MechanismError(source, key, f"{value!r} has a non-finite component",
                             "finite numbers")
    if unit:
        norm = float(np.linalg.norm(v))
        if norm <= 1e-12:
            raise MechanismError(source, key, "is a zero vector", "a non-zero direction")
        v = v / norm
    return float(v[0]), float(v[1]), float(v[2])


def _name(source, key, value):
    if not isinstance(value, str) or not value.strip():
        raise MechanismError(source, key, f"{value!r} is not a name", "a non-empty string")
    return value.strip()


def _freedoms_of_type(source, key, kind, axis, axis2):
    def need(vec, k):
        if vec is None:
            raise MechanismError(source, f"{key}.{k}", f"is required for a {kind} joint",
                                 "a 3-vector [x, y, z]")
        return vec

    if kind == "R":
        a = need(axis, "axis")
        return (Freedom("r", a, "r(axis)"),)
    if kind == "P":
        a = need(axis, "axis")
        return (Freedom("t", a, "t(axis)"),)
    if kind == "C":
        a = need(axis, "axis")
        return (Freedom("r", a, "r(axis)"), Freedom("t", a, "t(axis)"))
    if kind == "U":
        a, b = need(axis, "axis"), need(axis2, "axis2")
        if np.linalg.norm(np.cross(a, b)) < 1e-6:
            raise MechanismError(source, f"{key}.axis2", "is parallel to axis",
                                 "a second rotation axis not parallel to the first")
        return (Freedom("r", a, "r(axis)"), Freedom("r", b, "r(axis2)"))
    if kind == "S":
        return tuple(Freedom("r", UNIT[c], f"r{c}") for c in "xyz")
    if kind == "E":
        n = np.array(need(axis, "axis"))
        u = np.cross(n, [1.0, 0.0, 0.0])
        if np.linalg.norm(u) < 0.5:
            u = np.cross(n, [0.0, 1.0, 0.0])
        u = u / np.linalg.norm(u)
        w = np.cross(n, u)
        return (Freedom("r", tuple(n), "r(normal)"), Freedom("t", tuple(u), "t(in plane)"),
                Freedom("t", tuple(w), "t(in plane)"))
    raise AssertionError(kind)


def _free_list(source, key, value):
    if not isinstance(value, list) or not value:
        raise MechanismError(source, key, f"{value!r} is not a list of freed axes",
                             'a non-empty list of "rx", "ry", "rz", "tx", "ty", "tz" or '
                             "{r = [x, y, z]} / {t = [x, y, z]}")
    out = []
    for i, item in enumerate(value):
        k = f"{key}[{i}]"
        if isinstance(item, str):
            if item not in AXIS_NAMES:
                raise MechanismError(source, k, f"{item!r} is not a freed axis",
                                     ", ".join(f'"{a}"' for a in AXIS_NAMES)
                                     + " or {r = [x, y, z]} / {t = [x, y, z]}")
            out.append(Freedom(item[0], UNIT[item[1]], item))
        elif isinstance(item, dict):
            if len(item) != 1 or next(iter(item)) not in ("r", "t"):
                raise MechanismError(source, k, f"{item!r} is not a freed axis",
                                     "an inline table with exactly one key r or t: "
                                     "{r = [x, y, z]} or {t = [x, y, z]}")
            kind, vec = next(iter(item.items()))
            d = _vector(source, f"{k}.{kind}", vec, unit=True)
            out.append(Freedom(kind, d, f"{kind}({d[0]:.3g}, {d[1]:.3g}, {d[2]:.3g})"))
        else:
            raise MechanismError(source, k, f"{item!r} is not a freed axis",
                                 '"rx" ... "tz" or {r = [x, y, z]} / {t = [x, y, z]}')
    return tuple(out)


def mechanism_from_dict(data: dict, source: str = "<memory>") -> Mechanism:
    """Validate a parsed description (the TOML as a dict) and build the Mechanism."""
    _unknown_keys(source, "", data, TOP_KEYS)
    mech = data.get("mechanism")
    if not isinstance(mech, dict):
        raise MechanismError(source, "mechanism", "table is missing",
                             "[mechanism] with name and links")
    _unknown_keys(source, "mechanism.", mech, MECHANISM_KEYS)
    if "name" not in mech:
        raise MechanismError(source, "mechanism.name", "is missing", "a non-empty string")
    name = _name(source, "mechanism.name", mech["name"])
    links_raw = mech.get("links")
    if not isinstance(links_raw, list) or not links_raw:
        raise MechanismError(source, "mechanism.links", f"{links_raw!r} is not a list of links",
                             'a non-empty list of moving link names ("frame" is implicit)')
    links = []
    for i, ln in enumerate(links_raw):
        ln = _name(source, f"mechanism.links[{i}]", ln)
        if ln == FRAME:
            raise MechanismError(source, f"mechanism.links[{i}]", '"frame" is implicit',
                                 "moving links only")
        if ln in links:
            raise MechanismError(source, f"mechanism.links[{i}]", f"{ln!r} is listed twice",
                                 "unique names")
        links.append(ln)
    description = mech.get("description", "")
    if not isinstance(description, str):
        raise MechanismError(source, "mechanism.description", "is not a string", "text")
    tol = mech.get("rank_tolerance", DEFAULT_RANK_TOLERANCE)
    if (not isinstance(tol, (int, float)) or isinstance(tol, bool) or not math.isfinite(tol)
            or not 0.0 < tol < 1e-2):
        raise MechanismError(source, "mechanism.rank_tolerance", f"{tol!r} is out of range",
                             "a number between 0 and 1e-2 (relative singular-value cut-off)")

    joints_raw = data.get("joints")
    if not isinstance(joints_raw, list) or not joints_raw:
        raise MechanismError(source, "joints", "are missing",
                             "one or more [[joints]] tables with name, between, type/free, "
                             "point, axis")
    known = set(links) | {FRAME}
    joints: list[Joint] = []
    for i, jt in enumerate(joints_raw):
        key = f"joints[{i}]"
        if not isinstance(jt, dict):
            raise MechanismError(source, key, "is not a table", "[[joints]] tables")
        _unknown_keys(source, f"{key}.", jt, JOINT_KEYS)
        if "name" not in jt:
            raise MechanismError(source, f"{key}.name", "is missing", "a non-empty string")
        jname = _name(source, f"{key}.name", jt["name"])
        key = f"joints[{i}] ({jname})"
        if any(j.name == jname for j in joints):
            raise MechanismError(source, f"{key}.name", f"{jname!r} is used twice",
                                 "unique joint names")
        between = jt.get("between")
        if (not isinstance(between, list) or len(between) != 2
                or not all(isinstance(b, str) for b in between)):
            raise MechanismError(source, f"{key}.between", f"{between!r} is not a pair of links",
                                 "two link names [link, link]")
        for b in between:
            if b not in known:
                raise MechanismError(source, f"{key}.between", f"link {b!r} is not declared",
                                     "frame or one of mechanism.links: " + ", ".join(links))
        if between[0] == between[1]:
            raise MechanismError(source, f"{key}.between", "joins a link to itself",
                                 "two different links")
        if "point" not in jt:
            if jt.get("type") == "P":
                point = (0.0, 0.0, 0.0)
            else:
                raise MechanismError(source, f"{key}.point", "is missing",
                                     "the joint's point [x, y, z] in the assembled configuration")
        else:
            point = _vector(source, f"{key}.point", jt["point"], unit=False)
        axis = _vector(source, f"{key}.axis", jt["axis"], unit=True) if "axis" in jt else None
        axis2 = _vector(source, f"{key}.axis2", jt["axis2"], unit=True) if "axis2" in jt else None
        has_type, has_free = "type" in jt, "free" in jt
        if has_type == has_free:
            raise MechanismError(source, key, "needs exactly one of type or free",
                                 f"type = one of {', '.join(JOINT_TYPES)}; or free = [...]")
        if has_type:
            kind = jt["type"]
            if kind not in JOINT_TYPES:
                raise MechanismError(source, f"{key}.type", f"{kind!r} is not a joint type",
                                     ", ".join(JOINT_TYPES) + ' (or free = ["rx", "tx", ...])')
            if axis2 is not None and kind != "U":
                raise MechanismError(source, f"{key}.axis2", "is only used by U joints",
                                     "remove it or use type U")
            freedoms = _freedoms_of_type(source, key, kind, axis, axis2)
        else:
            kind = "free"
            if axis2 is not None:
                raise MechanismError(source, f"{key}.axis2", "is only used by U joints",
                                     "remove it or use type U")
            freedoms = _free_list(source, f"{key}.free", jt["free"])
        desc = jt.get("description", "")
        if not isinstance(desc, str):
            raise MechanismError(source, f"{key}.description", "is not a string", "text")
        joint = Joint(jname, (between[0], between[1]), kind, point, freedoms, axis, axis2, desc)
        if len(freedoms) > 6:
            raise MechanismError(source, f"{key}.free", f"has {len(freedoms)} entries",
                                 "at most 6 independent freed axes")
        if np.linalg.matrix_rank(joint.twists(), tol=1e-9) < len(freedoms):
            raise MechanismError(source, f"{key}.free", "freed axes are not independent",
                                 "independent rotations/translations (no axis twice)")
        joints.append(joint)

    _check_connected(source, links, joints)
    outputs, declared = _outputs(source, mech.get("outputs"), links, joints)
    return Mechanism(name, tuple(links), tuple(joints), outputs, source, description,
                     float(tol), declared)


def _check_connected(source, links, joints):
    unused = [ln for ln in links if not any(ln in j.between for j in joints)]
    if unused:
        raise MechanismError(source, "mechanism.links",
                             f"link(s) {unused} appear in no joint: not a connected mechanism",
                             "every moving link joined to the others and, through them, "
                             "to the frame")
    adj = {ln: set() for ln in list(links) + [FRAME]}
    for j in joints:
        a, b = j.between
        adj[a].add(b)
        adj[b].add(a)
    seen, stack = {FRAME}, [FRAME]
    while stack:
        for nb in adj[stack.pop()]:
            if nb not in seen:
                seen.add(nb)
                stack.append(nb)
    loose = [ln for ln in links if ln not in seen]
    if loose:
        if not adj[FRAME]:
            problem = "no joint touches the frame: not a connected mechanism"
        else:
            problem = (f"link(s) {loose} are not connected to the frame through any chain of "
                       f"joints: not a connected mechanism")
        raise MechanismError(source, "joints", problem,
                             'one connected graph of links and joints that contains "frame"')


def _outputs(source, raw, links, joints):
    if raw is None:
        ground = []
        for j in joints:
            for b in j.between:
                if b != FRAME and FRAME in j.between and b not in ground:
                    ground.append(b)
        return tuple(Output(b, None) for b in ground), False
    if not isinstance(raw, list) or not raw:
        raise MechanismError(source, "mechanism.outputs", f"{raw!r} is not a list of outputs",
                             'a non-empty list of "link" or "link.rx" ... "link.tz"')
    out = []
    for i, item in enumerate(raw):
        k = f"mechanism.outputs[{i}]"
        if not isinstance(item, str):
            raise MechanismError(source, k, f"{item!r} is not an output",
                                 '"link" or "link.rx" ... "link.tz"')
        link, _, coord = item.partition(".")
        if link not in links:
            raise MechanismError(source, k, f"link {link!r} is not a moving link",
                                 "one of " + ", ".join(links))
        if coord and coord not in AXIS_NAMES:
            raise MechanismError(source, k, f"coordinate {coord!r} is unknown",
                                 ", ".join(AXIS_NAMES))
        out.append(Output(link, coord or None))
    return tuple(out), True
