"""Property tests: whatever a user's file holds, the readers either load it or refuse it with
InputError (never another exception), and they never change the file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from juno.campaign import REQUIRED_COLUMNS, format_run_csv, load_campaign, read_run, read_run_csv, read_terrain_points
from juno.errors import InputError
from juno.pointcloud import format_xyz, read_xyz

SETTINGS = settings(
    max_examples=100,
    deadline=None,
    database=None,  # leave no .hypothesis folder in the work tree
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)


def base_run(n: int = 25) -> dict[str, np.ndarray]:
    t = np.arange(n) * 0.1
    sparse = np.where(np.arange(n) % 4 == 0, 1.0, np.nan)
    return {
        "time": t,
        "torque_left": 30.0 + t,
        "torque_right": 31.0 - t,
        "omega_left": 1.0 + 0.01 * t,
        "omega_right": np.full(n, 1.01),
        "pos_x": sparse * 0.3 * t,
        "pos_y": sparse * 0.0,
        "pos_z": sparse * 0.75,
        "yaw": np.where(np.arange(n) % 2 == 0, 0.01, np.nan),
        "drawbar_force": np.where(np.arange(n) % 3 == 0, 200.0, np.nan),
        "comment_col": np.full(n, 7.0),
    }


VALID_CSV = format_run_csv(base_run()).encode()
VALID_XYZ = ("# scan\n" + format_xyz(np.random.default_rng(0).uniform(-1, 1, (12, 3)))).encode()
NASTY = st.sampled_from(["abc", "nan", "inf", "-", "", " ", '"', '"1"', "1e999", "1,2", "\x00", "\ufeff", "١", "0x1", "1_0", "\r", "\n", "#"])
FRAGMENT = st.one_of(NASTY, st.text(max_size=6), st.binary(max_size=4).map(lambda b: b.decode("latin-1")))


def corrupt_csv(data: st.DataObject, raw: bytes) -> bytes:
    """Apply 1-4 random corruptions to a valid run CSV."""
    for _ in range(data.draw(st.integers(1, 4), label="n_edits")):
        kind = data.draw(st.sampled_from(["byte", "insert", "delete", "truncate", "swap", "inject", "dup_row", "drop_col"]))
        if kind == "byte" and raw:
            i = data.draw(st.integers(0, len(raw) - 1))
            raw = raw[:i] + bytes([data.draw(st.integers(0, 255))]) + raw[i + 1:]
        elif kind == "insert":
            i = data.draw(st.integers(0, len(raw)))
            raw = raw[:i] + data.draw(FRAGMENT).encode("utf-8", "surrogatepass") + raw[i:]
        elif kind == "delete" and raw:
            i = data.draw(st.integers(0, len(raw) - 1))
            raw = raw[:i] + raw[i + data.draw(st.integers(1, 40)):]
        elif kind == "truncate":
            raw = raw[: data.draw(st.integers(0, len(raw)))]
        else:
            try:
                lines = raw.decode("utf-8").split("\n")
            except UnicodeDecodeError:
                continue
            cells = [l.split(",") for l in lines]
            width = len(cells[0])
            if kind == "swap":  # swap two header names, or two whole columns
                i, j = data.draw(st.integers(0, width - 1)), data.draw(st.integers(0, width - 1))
                rows = cells[:1] if data.draw(st.booleans()) else cells
                for r in rows:
                    if len(r) > max(i, j):
                        r[i], r[j] = r[j], r[i]
            elif kind == "inject":
                r = data.draw(st.integers(0, len(cells) - 1))
                c = data.draw(st.integers(0, max(len(cells[r]) - 1, 0)))
                if cells[r]:
                    cells[r][c] = data.draw(FRAGMENT)
            elif kind == "dup_row" and len(cells) > 2:
                r = data.draw(st.integers(1, len(cells) - 2))
                cells.insert(r, list(cells[r]))
            elif kind == "drop_col":
                c = data.draw(st.integers(0, width - 1))
                cells = [[x for k, x in enumerate(r) if k != c] for r in cells]
            raw = "\n".join(",".join(r) for r in cells).encode("utf-8", "surrogatepass")
    return raw


def check_loaded_run(run, kind: str) -> None:
    t = run.time
    assert t.dtype == float and np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)
    for name in REQUIRED_COLUMNS[kind]:
        assert name in run.columns and np.any(~np.isnan(run[name]))
    for v in run.columns.values():
        assert v.shape == t.shape and v.dtype == float
        assert np.all(np.isfinite(v[~np.isnan(v)]))


@pytest.fixture(scope="module")
def work(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("props")


@SETTINGS
@given(data=st.data(), kind=st.sampled_from(["drawbar", "terrain"]))
def test_corrupted_run_csv_loads_or_is_refused(work: Path, data: st.DataObject, kind: str) -> None:
    raw = corrupt_csv(data, VALID_CSV)
    p = work / "run.csv"
    p.write_bytes(raw)
    try:
        run = read_run_csv(p, kind)
    except InputError as e:
        assert str(p) in str(e)
    else:
        check_loaded_run(run, kind)
    assert p.read_bytes() == raw


XYZ_ALPHABET = st.sampled_from(list("0123456789 \t,.-+eE#\n\rnaifx") + ["ply\n", "1e999", "\xff", "element vertex 3\n", "end_header\n"])


@SETTINGS
@given(
    text=st.one_of(
        st.lists(XYZ_ALPHABET, max_size=80).map("".join),
        st.none(),
    ),
    data=st.data(),
)
def test_random_xyz_loads_or_is_refused(work: Path, text: str | None, data: st.DataObject) -> None:
    if text is None:
        raw = corrupt_csv(data, VALID_XYZ)  # same byte-level corruptions on a valid cloud
    else:
        raw = text.encode("utf-8")
    suffix = data.draw(st.sampled_from([".xyz", ".ply", ".txt"]))
    p = work / f"cloud{suffix}"
    p.write_bytes(raw)
    try:
        pts = read_xyz(p)
    except InputError as e:
        assert p.name in str(e)
    else:
        assert pts.ndim == 2 and pts.shape[1] == 3 and pts.shape[0] >= 3
        assert np.all(np.isfinite(pts))
    assert p.read_bytes() == raw


@pytest.fixture(scope="module")
def campaign_root(work: Path) -> Path:
    root = work / "camp"
    (root / "runs").mkdir(parents=True)
    (root / "terrain").mkdir()
    (root / "runs" / "a.csv").write_bytes(VALID_CSV)
    terrain_run = {k: v for k, v in base_run().items() if k != "drawbar_force"}
    (root / "runs" / "b.csv").write_text(format_run_csv(terrain_run))
    (root / "terrain" / "scan.xyz").write_bytes(VALID_XYZ)
    return root


JSON_LEAF = st.one_of(
    st.none(), st.booleans(), st.integers(-(10**30), 10**30), st.floats(allow_nan=False), st.text(max_size=8),
    st.sampled_from(["runs/a.csv", "runs/b.csv", "terrain/scan.xyz", "drawbar", "terrain", "a", "b", "../x", "/etc", "runs"]),
)
JSON_ANY = st.recursive(JSON_LEAF, lambda kids: st.one_of(st.lists(kids, max_size=3), st.dictionaries(st.text(max_size=5), kids, max_size=3)), max_leaves=8)
RUN_KEYS = st.sampled_from(["id", "kind", "file", "steady_window", "terrain", "other"])
RUN_ENTRY = st.one_of(
    st.dictionaries(RUN_KEYS, JSON_ANY, max_size=6),
    st.fixed_dictionaries(
        {"id": st.sampled_from(["a", "b", "a b", ""]), "kind": st.sampled_from(["drawbar", "terrain", "x"]), "file": st.sampled_from(["runs/a.csv", "runs/b.csv", "runs/none.csv"])},
        optional={
            "steady_window": st.one_of(st.lists(st.floats(-5, 10), max_size=3), JSON_ANY),
            "terrain": st.sampled_from(["terrain/scan.xyz", "terrain/none.xyz", "runs/a.csv"]),
        },
    ),
)
MANIFEST = st.one_of(
    JSON_ANY,
    st.fixed_dictionaries(
        {"runs": st.one_of(st.lists(RUN_ENTRY, max_size=3), JSON_ANY)},
        optional={"name": JSON_ANY, "rover": st.one_of(st.dictionaries(st.text(max_size=6), JSON_LEAF, max_size=3), JSON_ANY), "extra": JSON_ANY},
    ),
)


VALID_MANIFEST = {
    "name": "props",
    "runs": [
        {"id": "a", "kind": "drawbar", "file": "runs/a.csv", "steady_window": [0.5, 1.5]},
        {"id": "b", "kind": "terrain", "file": "runs/b.csv", "terrain": "terrain/scan.xyz"},
    ],
    "rover": {"wheel.width": 0.254, "drive.mode": 1},
}


def mutate(data: st.DataObject, doc: object) -> object:
    """Replace or delete one random node of a JSON document (a near-valid manifest)."""
    if isinstance(doc, dict) and doc and data.draw(st.integers(0, 2)):
        key = data.draw(st.sampled_from(sorted(doc)))
        out = dict(doc)
        if data.draw(st.integers(0, 4)) == 0:
            del out[key]
        else:
            out[key] = mutate(data, doc[key])
        return out
    if isinstance(doc, list) and doc and data.draw(st.integers(0, 2)):
        i = data.draw(st.integers(0, len(doc) - 1))
        out = list(doc)
        out[i] = mutate(data, doc[i])
        return out
    return data.draw(JSON_ANY)


def snapshot(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@SETTINGS
@given(doc=MANIFEST, data=st.data())
def test_random_manifest_loads_or_is_refused(campaign_root: Path, doc: object, data: st.DataObject) -> None:
    if data.draw(st.booleans(), label="start from a valid manifest"):
        doc = VALID_MANIFEST
        for _ in range(data.draw(st.integers(0, 2))):
            doc = mutate(data, doc)
    text = json.dumps(doc, indent=data.draw(st.sampled_from([None, 2])))
    raw = text.encode()
    if data.draw(st.booleans(), label="corrupt bytes"):
        raw = corrupt_csv(data, raw)
    (campaign_root / "campaign.json").write_bytes(raw)
    before = snapshot(campaign_root)
    try:
        c = load_campaign(campaign_root)
        for spec in c.runs:  # the run files are valid; only the manifest's claims vary
            check_loaded_run(read_run(c, spec), spec.kind)
            if spec.kind == "terrain":
                assert read_terrain_points(c, spec).shape == (12, 3)
    except InputError as e:
        assert "campaign.json" in str(e) or "runs" in str(e) or "terrain" in str(e)
    assert snapshot(campaign_root) == before
