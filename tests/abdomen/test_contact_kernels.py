"""The compiled contact kernels against an independent numpy/trimesh implementation.

The reference below is the numpy version of ``detect_contacts`` and ``patch_force`` that the
compiled kernels replaced (vasim before the numba contact kernels): broad phase by
vectorised distances, closest points by ``trimesh.triangles.closest_point``, the nearest
face per sphere by a stable sort, the tip force by ``einsum``. The kernels must give the
same contacts and the same forces to round-off (1e-12 relative) on random poses over every
organ of the default abdomen, rest and deformed -- except where the nearest face is a tie
that round-off breaks (see ``ref_detect``): then the two may differ, and that must stay rare.
"""

from __future__ import annotations

import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from trimesh import triangles as tri_ops

from vasim.abdomen._contact_kernels import _closest, box_apart, cells_near, scatter_forces
from vasim.abdomen.contact import (
    STABILITY_FRACTION,
    ContactPatch,
    ContactResult,
    ToolPose,
    ToolShape,
    detect_contacts,
    patch_force,
    patch_force_into,
    point_segment_distance,
    sphere_offsets,
)
from vasim.abdomen.scene import load_scene
from vasim.abdomen.world import scene_models

# -- the numpy reference ---------------------------------------------------------------


def _axis(pose: ToolPose) -> tuple[np.ndarray, np.ndarray, float]:
    tip = np.asarray(pose.tip, dtype=np.float64)
    d = tip - np.asarray(pose.fulcrum, dtype=np.float64)
    length = float(np.linalg.norm(d))
    u = d / length if length > 1e-12 else np.array([0.0, 0.0, -1.0])
    return tip, u, length


def ref_tip_force(offsets, u, length, normals, stiffness, delta):
    a = np.clip(offsets / length, 0.0, 1.0) if length > 0 else np.zeros(len(offsets))
    un = normals @ u
    g = (1.0 - a)[:, None] * normals + (a * un)[:, None] * u[None, :]
    kd = stiffness * delta
    force = (kd[:, None] * g).sum(axis=0)
    stiff = -np.einsum("j,ja,jb->ab", stiffness, g, g)
    if length > 0 and np.any(a > 0):
        w = kd * a / length
        t = normals - un[:, None] * u[None, :]
        tw = (w[:, None] * t).sum(axis=0)
        proj = np.eye(3) - np.outer(u, u)
        stiff += np.outer(tw, u) + np.outer(u, tw) + float(w @ un) * proj
    return force, stiff


def ref_patch_force(patch: ContactPatch, pose: ToolPose):
    if patch.size == 0:
        return np.zeros(3), np.zeros((3, 3))
    tip, u, length = _axis(pose)
    c = tip[None, :] - patch.offsets[:, None] * u[None, :]
    delta = patch.radius - ((c - patch.points) * patch.normals).sum(axis=1)
    on = delta > 0.0
    return ref_tip_force(patch.offsets, u, length, patch.normals,
                         np.where(on, patch.stiffness, 0.0), np.where(on, delta, 0.0))


def ref_detect(x, faces, mass, pose, shape, *, dt, max_edge=None
               ) -> tuple[ContactResult, bool]:
    """The numpy detection, and whether the pose is ambiguous: some sphere has two nearest
    faces at the same distance (to 1e-9) with the centre behind one of them. Then either
    face is "the nearest" -- round-off decides -- and the two give different contacts (the
    face normal of a deep contact; touching or not): a discontinuity of the contact model
    itself, where no two implementations need agree."""
    r = shape.radius
    none = ContactResult.none(r), False
    tip, u, length = _axis(pose)
    offsets = sphere_offsets(pose, shape)
    centres = tip[None, :] - offsets[:, None] * u[None, :]
    if max_edge is None:
        e = x[faces[:, [1, 2, 0]]] - x[faces]
        max_edge = float(np.sqrt((e * e).sum(-1).max())) if len(faces) else 0.0
    margin = r + max_edge
    inbox = np.flatnonzero(((centres >= x.min(axis=0) - margin)
                            & (centres <= x.max(axis=0) + margin)).all(axis=1))
    if inbox.size == 0:
        return none
    sub = np.arange(inbox[0], inbox[-1] + 1)
    near = point_segment_distance(x, centres[sub[-1]], centres[sub[0]]) <= margin
    if not near.any():
        return none
    cand_f = np.flatnonzero(near[faces].any(axis=1))
    cand_nodes = np.flatnonzero(near)
    d_sn = np.linalg.norm(centres[sub, None, :] - x[None, cand_nodes, :], axis=2)
    close = d_sn <= margin
    rows = np.flatnonzero(close.any(axis=1))
    if rows.size == 0:
        return none
    s_near = sub[rows]
    local = np.full(len(x), -1, dtype=np.int64)
    local[cand_nodes] = np.arange(cand_nodes.size)
    fl = local[faces[cand_f]]
    ok = fl >= 0
    flc = np.where(ok, fl, 0)
    pair = (close[rows][:, flc] & ok[None, :, :]).any(axis=2)
    si_l, fi = np.nonzero(pair)
    if si_l.size == 0:
        return none
    si = s_near[si_l]
    tri = x[faces[cand_f]]
    c = centres[si]
    q = tri_ops.closest_point(tri[fi], c)
    n_f = np.cross(tri[fi, 1] - tri[fi, 0], tri[fi, 2] - tri[fi, 0])
    n_f /= np.maximum(np.linalg.norm(n_f, axis=1, keepdims=True), 1e-300)
    cq = c - q
    dist = np.linalg.norm(cq, axis=1)
    front = (cq * n_f).sum(axis=1) >= 0.0
    signed = np.where(front, dist, -dist)
    order = np.lexsort((np.abs(signed), si))
    first = np.ones(order.size, dtype=bool)
    first[1:] = si[order][1:] != si[order][:-1]
    pick = order[first]
    ambiguous = False
    for j, p in enumerate(order):
        nxt = order[j + 1] if j + 1 < order.size else -1
        if nxt >= 0 and si[nxt] == si[p] and first[j] and not (front[p] and front[nxt]):
            ambiguous |= bool(dist[nxt] - dist[p] <= 1e-9 * max(dist[p], 1e-12))
    delta = r - signed[pick]
    active = delta > 0.0
    if not active.any():
        return ContactResult.none(r), ambiguous
    pick = pick[active]
    delta = delta[active]
    normal = np.where((front[pick] & (dist[pick] > 1e-9))[:, None],
                      cq[pick] / np.maximum(dist[pick], 1e-300)[:, None], n_f[pick])
    face_nodes = faces[cand_f[fi[pick]]]
    bary = tri_ops.points_to_barycentric(tri[fi[pick]], q[pick])
    bary = np.clip(bary, 0.0, 1.0)
    bary /= bary.sum(axis=1, keepdims=True)
    m_eff = (bary * mass[face_nodes]).sum(axis=1)
    k = np.minimum(shape.contact_stiffness, STABILITY_FRACTION * m_eff / (dt * dt))
    f_j = (k * delta)[:, None] * normal
    ell = offsets[si[pick]]
    force = f_j.sum(axis=0)
    force_tip, stiff = ref_tip_force(ell, u, length, normal, k, delta)
    arm = centres[si[pick]] - np.asarray(pose.fulcrum, dtype=np.float64)
    torque = np.cross(arm, f_j).sum(axis=0)
    node_index = face_nodes.ravel()
    node_force = -(bary[:, :, None] * f_j[:, None, :]).reshape(-1, 3)
    patch = ContactPatch(q[pick].copy(), normal, k, ell, r)
    return ContactResult(force, force_tip, torque, stiff, node_index, node_force,
                         int(pick.size), float(delta.max()), patch), ambiguous


# -- comparisons -------------------------------------------------------------------------

RTOL = 1e-12


def close(a, b, scale: float) -> None:
    np.testing.assert_allclose(a, b, rtol=RTOL, atol=RTOL * max(scale, 1e-30))


def assert_same(got: ContactResult, ref: ContactResult) -> None:
    assert got.n_contacts == ref.n_contacts
    if not ref.in_contact:
        assert not got.in_contact and got.patch.size == 0
        return
    f = float(np.abs(ref.node_force).max())
    np.testing.assert_array_equal(np.sort(got.patch.offsets), np.sort(ref.patch.offsets))
    close(got.force, ref.force, f)
    close(got.force_tip, ref.force_tip, f)
    close(got.torque, ref.torque, f * 0.2)
    close(got.stiffness_tip, ref.stiffness_tip, float(np.abs(ref.patch.stiffness).max()))
    close(got.max_penetration, ref.max_penetration, ref.max_penetration)
    # the reaction forces per node (a tie between faces sharing the closest edge may pick
    # either face: the same forces on the same nodes)
    n = int(max(got.node_index.max(), ref.node_index.max())) + 1
    close(got.external_forces(n), ref.external_forces(n), f)
    close(got.patch.points, ref.patch.points, 0.1)
    close(got.patch.normals, ref.patch.normals, 1.0)
    close(got.patch.stiffness, ref.patch.stiffness, float(ref.patch.stiffness.max()))


SCENE = load_scene("default")
MODELS = [m for m in scene_models(SCENE) if m.kind != "wall"]
SHAPE = ToolShape()


def random_pose(rng: np.random.Generator, x: np.ndarray) -> ToolPose:
    """A tool from above, tip near a random surface node (inside or outside by <= 6 mm)."""
    target = x[rng.integers(len(x))] + rng.normal(0.0, 0.004, 3)
    fulcrum = target + np.array([*rng.normal(0.0, 0.05, 2), rng.uniform(0.05, 0.15)])
    return ToolPose(fulcrum, target)


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_detection_matches_the_numpy_reference_on_random_poses(model):
    rng = np.random.default_rng(zlib.crc32(model.name.encode()))
    surface = model.rest[: model.n_surface]
    hits = differ = 0
    for trial in range(60):
        # rest shape, then the shape pushed around (a deformed organ)
        x = np.array(model.rest)
        if trial % 2:
            x += rng.normal(0.0, 0.001, x.shape)
        pose = random_pose(rng, surface)
        dt = (1e-3, 4e-3)[trial % 2]
        got = detect_contacts(x, model.faces, model.mass, pose, SHAPE, dt=dt)
        ref, tie = ref_detect(x, np.asarray(model.faces), np.asarray(model.mass), pose, SHAPE,
                              dt=dt)
        try:
            assert_same(got, ref)
        except AssertionError:
            if not tie:
                raise
            differ += 1  # a tie that round-off broke the other way
        hits += ref.in_contact
        # the patch at the same pose reproduces the detection's tip force
        f, k = patch_force(got.patch, pose)
        rf, rk = ref_patch_force(got.patch, pose)
        scale = float(np.abs(got.node_force).max(initial=0.0))
        close(f, rf, scale)
        close(k, rk, float(np.abs(got.patch.stiffness).max(initial=0.0)))
    assert hits >= 30  # the poses do exercise contact
    assert differ <= 2  # ties broken differently stay rare (1 in 60 measured at most)


def test_given_max_edge_and_computed_max_edge_agree():
    model = MODELS[0]
    rng = np.random.default_rng(3)
    for _ in range(20):
        pose = random_pose(rng, model.rest[: model.n_surface])
        a = detect_contacts(model.rest, model.faces, model.mass, pose, SHAPE, dt=4e-3)
        e = model.rest[model.faces[:, [1, 2, 0]]] - model.rest[model.faces]
        h = float(np.sqrt((e * e).sum(-1).max()))
        b = detect_contacts(model.rest, model.faces, model.mass, pose, SHAPE, dt=4e-3,
                            max_edge=h)
        assert a.n_contacts == b.n_contacts
        np.testing.assert_array_equal(a.force, b.force)


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), m=st.integers(0, 12), length=st.floats(0.0, 0.2),
       moved=st.floats(0.0, 0.01))
def test_patch_force_matches_the_numpy_reference(seed, m, length, moved):
    rng = np.random.default_rng(seed)
    normals = rng.normal(size=(m, 3))
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    offsets = np.arange(m) * 0.0025
    tip = rng.normal(0.0, 0.01, 3)
    axis = rng.normal(size=3)
    fulcrum = tip - length * axis / np.linalg.norm(axis)
    points = (tip[None, :] - offsets[:, None] * (tip - fulcrum) / max(length, 1e-300)
              - 0.002 * normals + rng.normal(0.0, 0.001, (m, 3)))
    patch = ContactPatch(points, normals, rng.uniform(50.0, 400.0, m), offsets, 0.0025)
    pose = ToolPose(fulcrum, tip + rng.normal(0.0, moved, 3))
    f, k = patch_force(patch, pose)
    rf, rk = ref_patch_force(patch, pose)
    scale = 400.0 * 0.01 * max(m, 1)
    np.testing.assert_allclose(f, rf, rtol=RTOL, atol=RTOL * scale)
    np.testing.assert_allclose(k, rk, rtol=RTOL, atol=RTOL * scale / max(length, 1e-3) * 10)
    fo, ko = np.full(3, np.nan), np.full((3, 3), np.nan)
    on = patch_force_into(patch, np.asarray(fulcrum), np.asarray(pose.tip), fo, ko)
    np.testing.assert_array_equal(fo, f)
    np.testing.assert_array_equal(ko, k)
    _, u, _ = _axis(pose)
    c = pose.tip[None, :] - offsets[:, None] * u[None, :]
    assert on == int(((0.0025 - ((c - points) * normals).sum(axis=1)) > 0).sum())


def test_a_non_finite_pose_is_refused():
    model = MODELS[0]
    pose = ToolPose(np.array([0.0, 0.0, 0.1]), np.array([np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match="finite"):
        detect_contacts(model.rest, model.faces, model.mass, pose, SHAPE, dt=4e-3)


# -- the world's helpers against numpy ---------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), cells=st.integers(0, 40), bodies=st.integers(1, 5))
def test_cells_near_matches_the_vectorised_broad_phase(seed, cells, bodies):
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-0.1, 0.1, (cells, 3))
    r2 = rng.uniform(0.0, 0.03, cells) ** 2
    body = rng.integers(0, bodies, cells)
    ful = rng.uniform(-0.15, 0.15, 3)
    tip = ful + rng.normal(0.0, 0.08, 3) * rng.integers(0, 2)  # sometimes a point
    near, gap = cells_near(centres, r2, body, bodies, ful, tip)
    # the numpy version the world used before
    d = tip - ful
    pc = centres - ful
    dd = float(d @ d)
    u = np.clip(pc @ d / dd, 0.0, 1.0) if dd > 0 else np.zeros(len(pc))
    e = pc - u[:, None] * d
    dist2 = (e * e).sum(axis=1)
    hit = dist2 <= r2
    want = np.zeros(bodies, dtype=bool)
    want[body[hit]] = True
    np.testing.assert_array_equal(near, want)
    if not hit.any():
        ref_gap = float(np.min(np.sqrt(dist2) - np.sqrt(r2))) if cells else 0.0
        assert gap == pytest.approx(ref_gap, rel=1e-12, abs=1e-15)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 30), p=st.integers(0, 60))
def test_scatter_forces_is_np_add_at_to_the_bit(seed, n, p):
    rng = np.random.default_rng(seed)
    index = rng.integers(0, n, p)
    force = rng.normal(size=(p, 3))
    out = rng.normal(size=(n, 3))  # stale values are overwritten
    scatter_forces(out, index, force)
    want = np.zeros((n, 3))
    np.add.at(want, index, force)
    np.testing.assert_array_equal(out, want)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 30), margin=st.floats(0.0, 0.05))
def test_box_apart_matches_the_bounding_box_test(seed, n, margin):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-0.1, 0.1, (n, 3))
    a, b = rng.uniform(-0.2, 0.2, (2, 3))
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    want = bool(np.any(x.min(axis=0) - margin > hi) or np.any(x.max(axis=0) + margin < lo))
    assert box_apart(x, lo, hi, margin) == want


def test_a_patch_made_of_any_arrays_gives_the_same_force():
    normals = np.array([[0.0, 0.0, 1.0], [0.0, 0.6, 0.8]])
    plain = ContactPatch(np.zeros((2, 3)), normals, np.array([200.0, 300.0]),
                         np.array([0.0, 0.0025]), 0.0025)
    ro = normals.copy()
    ro.setflags(write=False)
    odd = ContactPatch(np.zeros((2, 6))[:, ::2], ro, [200, 300], (0.0, 0.0025), 0.0025)
    for a in (odd.points, odd.normals, odd.stiffness, odd.offsets):
        assert a.dtype == np.float64 and a.flags.c_contiguous and a.flags.writeable
    pose = ToolPose(np.array([0.0, 0.01, 0.1]), np.array([0.0, 0.0, 0.001]))
    for got, want in zip(patch_force(odd, pose), patch_force(plain, pose), strict=True):
        np.testing.assert_array_equal(got, want)


def test_inconsistent_arrays_are_refused_not_read_out_of_bounds():
    model = MODELS[0]
    pose = ToolPose(np.array([0.0, 0.0, 0.1]), np.array([0.0, 0.0, 0.0]))
    bad_faces = np.array(model.faces)
    bad_faces[0, 0] = model.n_nodes
    with pytest.raises(ValueError, match="faces index nodes"):
        detect_contacts(model.rest, bad_faces, model.mass, pose, SHAPE, dt=4e-3)
    with pytest.raises(ValueError, match="mass"):
        detect_contacts(model.rest, model.faces, model.mass[:-1], pose, SHAPE, dt=4e-3)
    with pytest.raises(ValueError, match="contact patch"):
        ContactPatch(np.zeros((2, 3)), np.zeros((3, 3)), np.zeros(2), np.zeros(2), 0.0025)


def test_closest_point_on_a_degenerate_triangle_does_not_divide_by_zero() -> None:
    # a == b: the denominator of the edge-ac branch was zero (ZeroDivisionError in numba)
    q = _closest(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0)
    assert all(np.isfinite(q))
    for p in ((0.5, 1.0, 0.0), (2.0, 0.0, 0.0), (1.0, 1.0, 1.0)):
        assert all(np.isfinite(_closest(*p, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0)))
        assert all(np.isfinite(_closest(*p, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)))
