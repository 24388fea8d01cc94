"""Trials of the three teleoperation modes through the study pipeline, checked from the store.

One session of a one-repetition copy of ``mrcp_vs_stdt`` (StdT, MRCP, MRCP+Cam) is run with
``vasim study run`` into a temporary database; every check reads the stored rows back and
recomputes from the stored samples with plain numpy (not ``vasim.records.trial_metrics``).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from vasim.cli import main
from vasim.operator.needle import needle_task
from vasim.operator.teleop_profile import NEUTRAL
from vasim.study.protocol import load_protocol
from vasim.study.store import TrialStore
from vasim.trials.registry import run_trial
from vasim.trials.teleop import CYCLE_DT, TISSUE_METRICS, TeleopTrial
from vasim.trials.teleop_config import TeleopTrialConfig

SEED = 3


def short_protocol(d: Path, repetitions: int = 1) -> Path:
    """``mrcp_vs_stdt`` with ``repetitions`` trials per mode (same questionnaires)."""
    text = load_protocol("mrcp_vs_stdt").text or ""
    text = text.replace("repetitions = 6", f"repetitions = {repetitions}")
    text = text.replace('name = "mrcp_vs_stdt"', 'name = "mrcp_short"')
    p = d / "mrcp_short.toml"
    p.write_text(text, encoding="utf-8")
    return p


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    d = tmp_path_factory.mktemp("mrcp_trials")
    db = d / "run.sqlite"
    assert main(["study", "run", "--protocol", str(short_protocol(d)), "--subject", "S01",
                 "--db", str(db), "--seed", str(SEED)]) == 0
    with TrialStore(db, readonly=True) as st:
        sched = st.schedule(1)
        by_mode = {row["condition"]: int(row["trial_id"]) for _, row in sched.iterrows()}
        data = {m: {"trial": st.trial(t), "samples": st.samples(t),
                    "metrics": st.trial_metrics(t).set_index("metric")["value"],
                    "events": st.events(t)} for m, t in by_mode.items()}
        status = st.sessions()["status"].tolist()
    return {"db": db, "data": data, "status": status}


def test_each_mode_runs_and_is_stored(session) -> None:
    assert session["status"] == ["completed"]
    data = session["data"]
    assert set(data) == {"stdt", "mrcp", "mrcp_cam"}
    n = needle_task().n_rings
    for mode, d in data.items():
        tr = d["trial"]
        assert tr["status"] == "completed" and tr["task"] == "needle"
        assert tr["config"]["mode"] == mode and tr["dt"] == CYCLE_DT
        s = d["samples"]
        np.testing.assert_allclose(np.diff(s["t"]), CYCLE_DT, atol=1e-9)
        assert s["goal_index"].iloc[-1] == n - 1      # the trial ends at the last pass
        assert d["metrics"]["completed"] == 1.0 and d["metrics"]["points_reached"] == n


def test_rings_are_passed_by_the_instrument_of_their_side(session) -> None:
    sides = needle_task().sides
    for d in session["data"].values():
        ev = d["events"]
        passed = [re.match(r"ring (\d+) passed \((\w+)\)", s).groups()
                  for s in ev.loc[ev["kind"] == "ring", "detail"]]
        assert [(int(i), side) for i, side in passed] == list(enumerate(sides))


def test_stdt_transfers_by_hand_with_regrasps_mrcp_transfers_automatically(session) -> None:
    data = session["data"]
    needed = needle_task().n_transfers
    std = data["stdt"]["metrics"]
    assert std["transfers"] == needed
    assert std["regrasps"] + std["misaligned_transfers"] >= 1
    kinds = set(data["stdt"]["events"]["kind"])
    assert {"transfer", "regrasp"} <= kinds or {"transfer", "misaligned_transfer"} <= kinds
    assert data["stdt"]["samples"]["clutch"].sum() == 0   # two masters, never decoupled
    for mode in ("mrcp", "mrcp_cam"):
        m = data[mode]["metrics"]
        assert m["regrasps"] == 0 and m["misaligned_transfers"] == 0
        assert m["transfers"] >= needed
        details = data[mode]["events"]["detail"]
        assert details.str.startswith("transfer_done").sum() == m["transfers"]
    # one master instead of two hands doing the transfers: shorter and less movement
    assert data["mrcp"]["metrics"]["completion_time"] < std["completion_time"]
    assert data["mrcp"]["metrics"]["master_path_l2"] < std["master_path_l2"]


def test_the_task_is_held_while_the_master_is_decoupled(session) -> None:
    for mode in ("mrcp", "mrcp_cam"):
        s = session["data"][mode]["samples"]
        m = session["data"][mode]["metrics"]
        held = (s["clutch"].to_numpy() == 1)
        assert held.any()
        assert held.sum() * CYCLE_DT == pytest.approx(m["tt_time"], abs=1e-9)
        x = s[["x_x", "x_y", "x_z"]].to_numpy()
        both = held[1:] & held[:-1]
        np.testing.assert_array_equal(x[1:][both], x[:-1][both])


def test_et_em_q_match_a_recomputation_from_the_samples(session) -> None:
    n = needle_task().n_rings
    for d in session["data"].values():
        s: pd.DataFrame = d["samples"]
        m = d["metrics"]
        t = s["t"].to_numpy()
        w = np.diff(np.concatenate([[0.0], t]))
        gi = s["goal_index"].to_numpy()
        x = s[["x_x", "x_y", "x_z"]].to_numpy()
        g = s[["g_x", "g_y", "g_z"]].to_numpy()
        passed = (gi == n - 1) & (np.linalg.norm(x - g, axis=1) <= needle_task().ring_radius)
        assert m["completion_time"] == pytest.approx(t[np.argmax(passed)], abs=1e-12)
        assert m["completion_time"] == pytest.approx(t[-1], abs=1e-12)
        assert m["path_l2"] == pytest.approx(np.linalg.norm(np.diff(x, axis=0), axis=1).sum(),
                                             rel=1e-12)
        # Q is the abdomen's accumulator over every instrument, at the physics rate (the
        # samples hold one force vector: the needle holder's); formerly this recomputed Q
        # from the samples, when the contact model held the needle holder only.
        summary = d["trial"]["summary"]
        for metric, field in TISSUE_METRICS.items():
            assert m[metric] == summary[f"tissue_{field}"], metric
        # the samples' contact flag (any instrument, one physics step per 18 ms cycle)
        # estimates the same contact time: each contact episode's two ends are each
        # misjudged by less than one cycle
        c = s["contact"].to_numpy() != 0
        assert abs(m["contact_time"] - w[c].sum()) <= 2 * CYCLE_DT * max(
            m["contact_count"], 1) + 1e-12
        fc = np.linalg.norm(s[["fc_x", "fc_y", "fc_z"]].to_numpy(), axis=1)
        assert not np.any(fc[~c])                   # a force only in contact
        assert m["target_displacement_max"] == pytest.approx(
            summary["tissue_target_displacement_max"])
        assert m["out_of_view_time"] == pytest.approx(w[s["in_view"].to_numpy() == 0].sum(),
                                                      abs=1e-12)


def test_the_camera_hand_moves_only_in_mrcp_cam(session) -> None:
    data = session["data"]
    cam = data["mrcp_cam"]
    assert cam["metrics"]["camera_path_l2"] > 0
    assert cam["metrics"]["master_path_l2"] > cam["metrics"]["camera_path_l2"]
    assert (cam["samples"]["zoom"] > 1.5).all()
    for mode in ("stdt", "mrcp"):
        assert data[mode]["metrics"]["camera_path_l2"] == 0
        assert (data[mode]["samples"]["zoom"] == 1.0).all()


def test_run_trial_dispatches_a_mode_and_same_seed_same_trial() -> None:
    cfg = TeleopTrialConfig(mode="stdt", seed=11, max_time=3.0, scene="none")
    a, tid = run_trial(cfg)
    assert tid is None and a.summary["mode"] == "stdt"
    b = TeleopTrial(cfg).run()
    np.testing.assert_array_equal(a.samples.view()["x"], b.samples.view()["x"])
    with pytest.raises(Exception, match="mode"):
        TeleopTrialConfig(mode="bimanual")


def test_safety_stops_are_acknowledged_and_too_many_end_the_trial() -> None:
    from vasim.trials.teleop import FAULT_ACK_TIME, MAX_SAFETY_STOPS

    tr = TeleopTrial(TeleopTrialConfig(mode="mrcp", seed=2, max_time=60.0, scene="none"),
                     n_rings=2)
    cycles = tr.cycles()
    for _ in range(20):
        next(cycles)
    # an obstacle around the holder's tool tip: every move of RSel now collides
    tr.station.world.add_sphere("block", tr.station.tip(tr.state.holder), 0.004)
    for _ in cycles:
        pass
    res = tr.result()
    ev = [(t, d) for t, k, d in res.events if k in ("mrcp", "aborted")]
    stops = [t for t, d in ev if d.startswith("rsel_collision")]
    acks = [t for t, d in ev if d == "safety stop acknowledged"]
    assert len(stops) == MAX_SAFETY_STOPS + 1 and len(acks) == MAX_SAFETY_STOPS
    assert ev[-1][1] == "repeated safety stops"
    wait = tr.profile.reaction_delay + FAULT_ACK_TIME
    for t_stop, t_ack in zip(stops, acks, strict=False):
        assert t_ack - t_stop == pytest.approx(wait, abs=CYCLE_DT + 1e-9)
    assert res.summary["safety_stops"] == MAX_SAFETY_STOPS + 1
    assert not res.summary["finished"]
    x = res.samples.view()["x"]
    after = res.samples.view()["t"] >= stops[0]
    np.testing.assert_array_equal(x[after], np.repeat(x[after][:1], after.sum(), axis=0))


def test_the_free_instrument_touching_tissue_counts_in_q() -> None:
    # StdT carries the needle with the right instrument; the left one, idle, is put into
    # the tissue straight under its tip: its contact is Q's although it holds nothing
    tr = TeleopTrial(TeleopTrialConfig(mode="stdt", seed=11, max_time=1.0))
    st = tr.station
    assert tr.abdomen is not None and list(tr.instruments()) == ["right", "left", "camera"]
    tip = st.tip("left")
    surf = np.concatenate([o.surface for o in tr.abdomen.latest.organs
                           if o.name != "abdominal_wall"])
    below = surf[np.linalg.norm(surf[:, :2] - tip[:2], axis=1) < 0.004]
    target = below[np.argmax(below[:, 2])] - np.array([0.0, 0.0, 0.004])
    q = st.arms["left"].ik(target, None, st.world.configuration("left"))
    assert q is not None
    st.world.set_configuration("left", q)
    res = tr.run()
    assert tr.state.holder == "right" and tr.state.snap is not None
    assert tr.state.snap.tool("left").in_contact and not tr.state.snap.tool("camera").in_contact
    m = res.trial_metrics
    assert m["contact_time"] == pytest.approx(tr.abdomen.quality.contact_time)
    assert m["contact_time"] > 0.9 and m["accumulated_force"] > 0
    view = res.samples.view()
    assert view["contact"][5:].all()
    # the samples' force is the holder's: only the left instrument presses here
    right = np.linalg.norm(view["f_contact"], axis=1)
    assert m["accumulated_force"] > float((right * CYCLE_DT).sum())


def test_every_mode_follows_the_same_needle_route() -> None:
    # the route rule (vasim.operator.needle.needle_route): the same waypoints in every mode,
    # via points at the midline 1.5 cm above the higher ring between rings on different
    # sides; static rings (no tissue), so the waypoints themselves must agree exactly
    from vasim.operator.needle import VIA_HEIGHT, handover_point, needle_route

    task = needle_task(3)
    points, kinds = needle_route(task.rings, task.sides)
    assert kinds == (0, -1, 1, -1, 2)
    np.testing.assert_allclose(points[1], [0.0, 0.5 * (task.rings[0, 1] + task.rings[1, 1]),
                                           task.rings[:2, 2].max() + VIA_HEIGHT])
    np.testing.assert_array_equal(points[3], handover_point(task.rings[1], task.rings[2]))
    visited = {}
    for mode in ("stdt", "mrcp"):
        # the route is the station's and the task's: the person as the scripted operator is,
        # without mode penalties (NEUTRAL, the default: the mechanism alone)
        tr = TeleopTrial(TeleopTrialConfig(mode=mode, seed=SEED, max_time=60.0, scene="none"),
                         n_rings=3, effects=NEUTRAL)
        res = tr.run()
        assert res.summary["finished"]
        log = tr.state.route_log
        assert [k for k, *_ in log] == list(kinds)
        times = [t for _, t, _, _ in log]
        assert times == sorted(times)
        for _, _, w, x in log:                    # each reached within the ring radius
            assert np.linalg.norm(x - w) <= task.ring_radius + 1e-12
        np.testing.assert_allclose(np.array([w for *_, w, _ in log]), points, atol=1e-12)
        # the needle crosses the midline (x = 0) above both rings it is between: a
        # straight ring-to-ring path would cross at their mean height, below the higher
        x = res.samples.view()["x"]
        gi = res.samples.view()["goal_index"]
        cross = np.nonzero(np.sign(x[1:, 0]) != np.sign(x[:-1, 0]))[0]
        assert len(cross) >= 2
        for c in cross:
            i = int(gi[c + 1])
            assert i >= 1
            assert max(x[c, 2], x[c + 1, 2]) > task.rings[i - 1:i + 1, 2].max()
        visited[mode] = np.array([x for *_, x in log])
    # both modes pass every waypoint within twice the ring radius of each other
    gap = np.linalg.norm(visited["stdt"] - visited["mrcp"], axis=1)
    assert gap.max() <= 2 * task.ring_radius


def test_the_stored_trials_pass_the_via_points_in_every_mode(session) -> None:
    # with tissue the rings ride on the bowel: each mode logs the via points it passed,
    # where they were that cycle; the needle sample of that cycle is within the ring radius
    # of it, and in every mode each via point is the rest route's (needle_route of the
    # rings at rest) moved at most by the rings' motion: the loops' breathing (at most 4 mm,
    # intestine_3/4/5 in protocols/scenes/default.toml) plus the trial's largest target
    # displacement by the instruments (and the event's 0.01 mm rounding)
    from vasim.operator.needle import needle_route

    task = needle_task()
    rest, kinds = needle_route(task.rings, task.sides)
    rest_vias = rest[np.array(kinds) == -1]
    for d in session["data"].values():
        ev = d["events"]
        rows = ev[ev["kind"] == "route"]
        assert len(rows) == task.n_rings - 1
        s = d["samples"]
        x = s[["x_x", "x_y", "x_z"]].to_numpy()
        pts = []
        for _, r in rows.iterrows():
            m = re.search(r"at (-?[\d.]+), (-?[\d.]+), (-?[\d.]+) mm", r["detail"])
            w = np.array([float(v) for v in m.groups()]) * 1e-3
            k = int(np.argmin(np.abs(s["t"].to_numpy() - r["t"])))
            assert np.linalg.norm(x[k] - w) <= task.ring_radius + 1e-5
            pts.append(w)
        moved = np.linalg.norm(np.array(pts) - rest_vias, axis=1)
        assert moved.max() <= 0.004 + d["metrics"]["target_displacement_max"] + 1e-5


def test_the_report_tables_et_em_and_q_of_the_stored_trials(session, tmp_path: Path) -> None:
    # issue #21 §4: tables/mrcp_descriptives.csv keeps metric, mode, mean for ET, EM and Q;
    # Q is the rings' deformation [mm s] (vasim.trials.teleop_quality) as stored per trial
    from vasim.operator.learning import OPERATOR_LABEL
    from vasim.study.report import build_report

    build_report(session["db"], tmp_path / "r", protocol="mrcp_short")
    desc = pd.read_csv(tmp_path / "r" / "tables" / "mrcp_descriptives.csv")
    label = {"stdt": "StdT", "mrcp": "MRCP", "mrcp_cam": "MRCP+Cam"}
    for key, metric in (("ET", "completion_time"), ("EM", "path_l2"),
                        ("Q", "target_deformation")):
        rows = desc[desc["metric"] == key].set_index("mode")
        assert set(rows.index) == set(label.values())
        for mode, d in session["data"].items():
            assert rows.loc[label[mode], "mean"] == pytest.approx(d["metrics"][metric])
    with TrialStore(session["db"], readonly=True) as st:
        assert st.sessions()["operator"].tolist() == [OPERATOR_LABEL]
    for d in session["data"].values():       # the trial knows its mode's practice
        assert d["trial"]["config"]["mode_practice"] == 0
        assert d["metrics"]["target_deformation"] >= 0.0


class _StillHand:
    """A hand that never moves its master and never reaches a goal."""

    j = 0
    done = False

    def move(self, dt: float, seen: np.ndarray, goal: np.ndarray, zoom: float) -> np.ndarray:
        return np.zeros(3)

    def check(self, position: np.ndarray, goal: np.ndarray) -> bool:
        return False


class _RecordingHands:
    """A ``HandFactory`` that records every request and every move of its hands, and hands
    out ``inner``'s hands (None: still hands)."""

    def __init__(self, inner=None) -> None:
        self.inner = inner
        self.requests: list = []
        self.moves = 0

    def __call__(self, request):
        self.requests.append(request)
        hand = self.inner(request) if self.inner is not None else _StillHand()
        factory = self

        class Recorded:
            @property
            def j(self) -> int:
                return hand.j

            @property
            def done(self) -> bool:
                return hand.done

            def move(self, *a):
                factory.moves += 1
                return hand.move(*a)

            def check(self, *a):
                return hand.check(*a)

        return Recorded()


@pytest.mark.parametrize("mode", ["stdt", "mrcp"])
def test_the_trial_s_hands_come_from_its_hand_factory(mode: str) -> None:
    from vasim.trials.teleop import OPERATOR_SUBSTEPS
    from vasim.trials.teleop_hands import ScriptedHands

    cfg = TeleopTrialConfig(mode=mode, seed=SEED, max_time=4.0, scene="none")
    plain = TeleopTrial(cfg, n_rings=2)
    ref = plain.run()
    # the default factory is the scripted person's: the same hands through the hook give
    # the same trial, bit for bit, and every path and every hand step went through it
    m = plain.model
    rec = _RecordingHands(ScriptedHands(m.adjustment, m.task, cfg.practice))
    tr = TeleopTrial(cfg, n_rings=2, hand_factory=rec)
    res = tr.run()
    np.testing.assert_array_equal(res.samples.view()["x"], ref.samples.view()["x"])
    assert res.trial_metrics == ref.trial_metrics
    first = rec.requests[0]
    np.testing.assert_array_equal(first.start, tr.task.start)
    assert first.carry and len(rec.requests) >= 2
    assert len({r.seed for r in rec.requests}) == len(rec.requests)   # one seed per path
    assert rec.moves >= OPERATOR_SUBSTEPS * (tr.state.k + 1) // 2
    # hands that do not move: the needle stays where it started
    still = _RecordingHands()
    res = TeleopTrial(cfg, n_rings=2, hand_factory=still).run()
    assert len(still.requests) == 1 and still.moves == OPERATOR_SUBSTEPS * (res.summary["steps"])
    x = res.samples.view()["x"]
    np.testing.assert_allclose(x, np.repeat(x[:1], len(x), axis=0), atol=1e-9)
    assert not res.summary["finished"]
