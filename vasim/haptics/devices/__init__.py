"""The input/force devices of vasim and what each needs to be available.

``DEVICES`` is a registry (a duplicate name raises ``ValueError``): one
:class:`DeviceInfo` per device kind with a ``probe()`` that reports, without side effects
beyond opening and closing the device, whether it can be used now and, if not, exactly
what is missing — a Python package, a runtime library, or the hardware
(:class:`Missing`). ``vasim devices`` prints these reports.

Device modules are imported lazily (the OpenHaptics one only when probed or used), so
importing this package costs nothing and never touches a device SDK.

Example:
    >>> [info.name for info in DEVICES.values()]
    ['emulator', 'scripted', 'browser', 'laparoscopic', 'replay', 'openhaptics']
    >>> DEVICES["emulator"].probe().available
    True
"""

from __future__ import annotations

import importlib.util
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

MissingKind = Literal["package", "runtime library", "hardware"]


@dataclass(frozen=True)
class Missing:
    """One thing a device needs and does not have.

    Attributes:
        kind: ``"package"``, ``"runtime library"`` or ``"hardware"``.
        what: the missing thing (``pyopenhaptics``, ``libHD.so``, ``Phantom Omni / Touch``).
        hint: how to get it.
    """

    kind: MissingKind
    what: str
    hint: str


@dataclass(frozen=True)
class Availability:
    """A probe's answer: available, or what is missing; ``detail`` adds context."""

    available: bool
    missing: tuple[Missing, ...] = ()
    detail: str = ""

    def to_dict(self) -> dict[str, object]:
        return {"available": self.available, "detail": self.detail,
                "missing": [{"kind": m.kind, "what": m.what, "hint": m.hint}
                            for m in self.missing]}


@dataclass(frozen=True)
class DeviceInfo:
    """A registered device kind: name, one-line summary and availability probe."""

    name: str
    summary: str
    probe: Callable[[], Availability] = field(repr=False)


class DeviceRegistry(dict[str, DeviceInfo]):
    """Device kinds by name, in registration order."""

    def add(self, info: DeviceInfo) -> DeviceInfo:
        """Registers ``info``; raises ``ValueError`` for a duplicate name."""
        if info.name in self:
            raise ValueError(f"device {info.name!r} is already registered")
        self[info.name] = info
        return info


def _always() -> Availability:
    return Availability(True)


def _probe_browser() -> Availability:
    if importlib.util.find_spec("viser") is None:
        return Availability(False, (Missing("package", "viser",
                                            "pip install vasim (viser is a dependency)"),))
    return Availability(True, detail="fed by `vasim serve`: drag the gizmo on the tool "
                                     "tip (Experimenter tab, input: browser)")


def _probe_openhaptics() -> Availability:
    """Package, runtime library, hardware — in that order (each needs the previous)."""
    from vasim.haptics.devices import openhaptics as oh

    try:
        sdk = oh._import_sdk()
    except ImportError:
        missing = [Missing("package", "pyopenhaptics", oh.INSTALL_HINT)]
        if not oh.runtime_loadable():
            missing.append(Missing("runtime library", oh.RUNTIME_LIBRARY, oh.RUNTIME_HINT))
        return Availability(False, tuple(missing))
    except OSError as exc:
        return Availability(False, (Missing("runtime library", oh.RUNTIME_LIBRARY,
                                            oh.RUNTIME_HINT),), detail=str(exc))
    from vasim.core.errors import DeviceError

    try:
        handle = oh.open_device(sdk, "Default Device")
    except DeviceError as exc:
        return Availability(False, (Missing("hardware", "Phantom Omni / Geomagic Touch",
                                            str(exc)),))
    try:
        with oh._quiet():
            detail = f"{sdk.hd.get_vendor()} {sdk.hd.get_model()}".strip()
    except Exception:  # the name is a nicety
        detail = ""
    finally:
        with oh._quiet():
            sdk.hd.close_device(handle)
    return Availability(True, detail=detail)


DEVICES = DeviceRegistry()
DEVICES.add(DeviceInfo("emulator", "emulated Phantom Omni: stylus mass, hand impedance, "
                       "force limits (vasim.haptics.devices.emulator)", _always))
DEVICES.add(DeviceInfo("scripted", "simulated operator moving along the task "
                       "(vasim.operator.device)", _always))
DEVICES.add(DeviceInfo("browser", "pointer drags in the viewer, resampled to 1 kHz "
                       "(vasim.haptics.devices.browser)", _probe_browser))
DEVICES.add(DeviceInfo("laparoscopic", "an instrument pivoting about its trocar, moved with "
                       "the mouse (pointer lock), keyboard or a gamepad in the viewer "
                       "(vasim.haptics.devices.laparoscopic)", _probe_browser))
DEVICES.add(DeviceInfo("replay", "plays back a recorded device stream (.npz) exactly "
                       "(vasim.haptics.devices.replay)", _always))
DEVICES.add(DeviceInfo("openhaptics", "Phantom Omni / Geomagic Touch through OpenHaptics "
                       "(vasim.haptics.devices.openhaptics)", _probe_openhaptics))


def probe_all() -> list[tuple[DeviceInfo, Availability]]:
    """Every registered device with its availability (a failing probe reports its error)."""
    out = []
    for info in DEVICES.values():
        try:
            avail = info.probe()
        except Exception as exc:
            avail = Availability(False, detail=f"probe failed: {type(exc).__name__}: {exc}")
        out.append((info, avail))
    return out


__all__ = ["DEVICES", "Availability", "DeviceInfo", "DeviceRegistry", "Missing", "probe_all"]
