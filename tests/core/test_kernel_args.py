"""One array type per compiled-kernel argument (vasim/core/kernel_args.py, issue #31): the
helpers keep values and say what they promise about copies and flags, and the kernels' call
sites compile each kernel once whether the caller holds read-only or writable arrays (a
second specialization would show as a new entry in the dispatcher's ``signatures``)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.abdomen.test_contact import FACES, MASS, SHAPE, X, vertical_tool
from tests.abdomen.test_integrate import spring_mass
from vasim.abdomen import _contact_kernels, _kernels
from vasim.abdomen.contact import detect_contacts
from vasim.abdomen.integrate import OrganSolver
from vasim.core.kernel_args import readonly_c, writable_c
from vasim.mrcp import _ik_kernels, backend, dh

arrays = hnp.arrays(st.sampled_from([np.float64, np.float32, np.int64]),
                    hnp.array_shapes(min_dims=1, max_dims=3, max_side=4),
                    elements=st.integers(-100, 100))
layouts = st.sampled_from(["c", "fortran", "strided", "readonly"])


def _laid_out(a: np.ndarray, layout: str) -> np.ndarray:
    if layout == "fortran":
        return np.asfortranarray(a)
    if layout == "strided":
        return np.repeat(a, 2, axis=0)[::2]
    if layout == "readonly":
        r = a.copy()
        r.flags.writeable = False
        return r
    return a


@settings(max_examples=200, deadline=None)
@given(arrays, layouts, st.sampled_from([np.float64, np.int64]))
def test_both_helpers_keep_the_values_and_give_the_promised_type(
        a: np.ndarray, layout: str, dtype: Any) -> None:
    a = _laid_out(a, layout)
    before = a.copy()
    writable_before = a.flags.writeable
    for helper, writable in ((readonly_c, False), (writable_c, True)):
        out = helper(a, dtype)
        assert type(out) is np.ndarray and out.dtype == dtype and out.flags.c_contiguous
        assert out.flags.writeable is writable
        np.testing.assert_array_equal(out, before.astype(dtype))
        assert a.flags.writeable is writable_before        # the caller's array untouched
    fits = a.dtype == dtype and a.flags.c_contiguous
    # no copy of an array that already fits: readonly_c views it, writable_c returns it
    assert np.shares_memory(readonly_c(a, dtype), a) is fits
    assert (writable_c(a, dtype) is a) is (fits and a.flags.writeable)


def test_a_writable_copy_never_writes_through_to_a_read_only_array() -> None:
    a = np.arange(4.0)
    a.flags.writeable = False
    w = writable_c(a)
    w[0] = 99.0
    assert a[0] == 0.0


def _compiled_once(kernel: Any, call: Callable[[bool], object]) -> None:
    """``call(False)`` then ``call(True)`` (writable, then read-only caller arrays) add no
    specialization to ``kernel`` after the first call's."""
    call(False)
    n = len(kernel.signatures)
    call(True)
    assert len(kernel.signatures) == n, kernel.signatures


def _frozen(a: np.ndarray, readonly: bool) -> np.ndarray:
    out = np.array(a)
    out.flags.writeable = not readonly
    return out


RX = dh.load_robot("rx60b")
Q = np.array([0.1, -0.4, 1.2, 0.3, -0.5, 0.2])


@pytest.mark.parametrize("name", ["frames_one", "frames_many", "position_dls", "wrap_clip"])
def test_a_robot_kernel_is_compiled_once_for_read_only_and_writable_callers(name: str) -> None:
    lower, upper = RX.lower, RX.upper
    target = dh.fk(RX, Q)[0] + 0.01
    calls: dict[str, tuple[Any, Callable[[bool], object]]] = {
        "frames_one": (dh._chain_kernel, lambda ro: dh.frames_one(RX, _frozen(Q, ro))),
        "frames_many": (dh._many_kernel,
                        lambda ro: dh.frames_many(RX, _frozen(np.stack([Q, -Q]), ro))),
        "position_dls": (dh._position_dls_kernel,
                         lambda ro: dh.position_dls(RX, _frozen(Q, ro), _frozen(target, ro))),
        "wrap_clip": (dh._wrap_clip, lambda ro: dh.wrap_clip(
            _frozen(Q + 7.0, ro), _frozen(lower, ro), _frozen(upper, ro))),
    }
    _compiled_once(*calls[name])


def test_the_full_pose_ik_is_compiled_once_for_read_only_and_writable_callers() -> None:
    arm = backend.PybulletArm(RX)
    try:
        p, r = arm.tcp_pose(Q)

        def call(ro: bool) -> object:
            return arm._refine(_frozen(Q + 0.05, ro), _frozen(p, ro), _frozen(r, ro),
                               1e-6, 1e-6)
        _compiled_once(_ik_kernels.pose_dls, call)
    finally:
        arm.close()


def test_contact_detection_is_compiled_once_for_read_only_and_writable_organs() -> None:
    def call(ro: bool) -> object:
        return detect_contacts(_frozen(X, ro), _frozen(FACES, ro), _frozen(MASS, ro),
                               vertical_tool(0.004), SHAPE, dt=1e-3)
    _compiled_once(_contact_kernels.tool_contacts, call)


def test_the_organ_step_is_compiled_once_for_read_only_and_writable_anchor_targets() -> None:
    model = spring_mass(100.0, 1.0, 0.05)
    solver = OrganSolver(model, 1e-3)
    state = solver.initial_state()
    target = model.rest[model.anchors]

    def call(ro: bool) -> object:
        return solver.step(state, _frozen(target, ro))
    _compiled_once(_kernels.implicit_step, call)
