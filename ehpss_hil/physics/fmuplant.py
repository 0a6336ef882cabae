"""The user's FMI 2.0/3.0 co-simulation FMU as the emulated plant (fmpy), behind the one
:class:`~.plant.Plant` protocol (docs/fmu.md).

Each sample: the coil current (limited by the bench's amplifier, ``current_limit_a``) is set on
the FMU's mapped input, the FMU is stepped over the sample period — in equal sub-steps when its
preferred step (:attr:`~.fmucheck.FmuDescription.step_s`) is shorter — and the mapped outputs are
read. Actuator faults the map names are set on their inputs when they change, and the outputs
read again (an output may feed an input through at once: the actual spool k_LOE·x_v). The sensor, noise
and bus faults stay in :mod:`ehpss_hil.emulation` around this plant.

The FMU is extracted once per plant into a temporary folder (removed with the plant) and
instantiated at :meth:`FmuPlant.reset` (a fresh instance: FMI's ``reset`` is optional in
practice). A failing load, instantiation or initialization is a
:class:`~ehpss_hil.errors.ConfigError` (exit 2); a failing step, or a non-finite output, a
:class:`~ehpss_hil.errors.PlantStepError` naming the FMU, the FMI function, its status and the time.
"""

from __future__ import annotations

import ctypes
import logging
import math
import shutil
import tempfile
import weakref
from pathlib import Path
from typing import Any

from ..errors import ConfigError, PlantStepError, one_line
from ..extras import require
from .faults import FaultState
from .fmucheck import FmuDescription, check_fmu
from .fmumap import ACTUATOR_FAULTS, FmuMap

require("fmu", "plant: {model: fmu}", ("fmpy",))  # before fmpy's first import below
from fmpy.fmi1 import FMICallException  # noqa: E402  (fmpy: the FMU plant's own dependency)

log = logging.getLogger("ehpss_hil.fmu")

#: FMI status names by code (the same codes in FMI 2.0 and 3.0)
STATUS_NAMES = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")
#: the outputs read after each step, in this order (current_echo_a only when mapped)
OUTPUT_KEYS = ("position_m", "spool_m", "load_pressure_pa", "current_echo_a")


def status_name(status: int) -> str:
    """``Error`` for 3, …; ``status 9`` for a code FMI does not define."""
    return STATUS_NAMES[status] if 0 <= status < len(STATUS_NAMES) else f"status {status}"


def _fmu_log(status: int, message: bytes | None) -> None:
    """An FMU's log message → this module's logger (warning and worse as warnings), one line."""
    text = one_line((message or b"").decode("utf-8", "replace"))
    log.log(logging.WARNING if status >= 1 else logging.DEBUG, "FMU %s: %s", status_name(status), text)


class _Slave:
    """One instance of the FMU with the calls the plant makes (FMI 2.0 or 3.0, fmpy's low-level
    functions: each raises fmpy's FMICallException with the status on Discard or worse)."""

    def __init__(self, desc: FmuDescription, unzipdir: str) -> None:
        from fmpy.fmi2 import FMU2Slave
        from fmpy.fmi3 import FMU3Slave

        kwargs = {
            "guid": desc.guid,
            "unzipDirectory": unzipdir,
            "modelIdentifier": desc.model_identifier,
            "instanceName": "ehpss-plant",
        }
        self.v3 = desc.fmi_major == 3
        self.fmu: Any = FMU3Slave(**kwargs) if self.v3 else FMU2Slave(**kwargs)
        self.c: Any = None
        self._flags = [ctypes.c_bool() for _ in range(3)]
        self._last = ctypes.c_double()

    def start(self) -> None:
        """Instantiate and enter initialization mode at t = 0."""
        if self.v3:
            from fmpy.fmi3 import fmi3LogMessageCallback

            self._cb: Any = fmi3LogMessageCallback(lambda _env, status, _cat, msg: _fmu_log(status, msg))
            self.fmu.instantiate(logMessage=self._cb)
            self.c = self.fmu.component
            self.fmu.enterInitializationMode(startTime=0.0)
        else:
            from fmpy.fmi2 import calloc as fmi_calloc
            from fmpy.fmi2 import (
                fmi2CallbackAllocateMemoryTYPE,
                fmi2CallbackFreeMemoryTYPE,
                fmi2CallbackFunctions,
                fmi2CallbackLoggerTYPE,
            )
            from fmpy.fmi2 import free as fmi_free
            from fmpy.logging import addLoggerProxy

            cb = fmi2CallbackFunctions()
            cb.logger = fmi2CallbackLoggerTYPE(lambda _c, _n, status, _cat, msg: _fmu_log(status, msg))
            cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmi_calloc)
            cb.freeMemory = fmi2CallbackFreeMemoryTYPE(fmi_free)
            addLoggerProxy(ctypes.byref(cb))
            self._cb = cb
            self.fmu.instantiate(callbacks=cb)
            self.c = self.fmu.component
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()

    def set_real(self, vrs: Any, values: Any, n: int) -> None:
        if self.v3:
            self.fmu.fmi3SetFloat64(self.c, vrs, n, values, n)
        else:
            self.fmu.fmi2SetReal(self.c, vrs, n, values)

    def get_real(self, vrs: Any, values: Any, n: int) -> None:
        if self.v3:
            self.fmu.fmi3GetFloat64(self.c, vrs, n, values, n)
        else:
            self.fmu.fmi2GetReal(self.c, vrs, n, values)

    def do_step(self, t_s: float, h_s: float) -> bool:
        """One communication step; False when an FMI 3.0 FMU asks to terminate."""
        if not self.v3:
            self.fmu.fmi2DoStep(self.c, t_s, h_s, 1)
            return True
        event, terminate, early = self._flags
        by = ctypes.byref
        self.fmu.fmi3DoStep(self.c, t_s, h_s, True, by(event), by(terminate), by(early), by(self._last))
        return not terminate.value

    def free(self) -> None:
        """Terminate and free the instance and its library (errors ignored: it is going)."""
        if self.c is None:
            return
        try:
            self.fmu.terminate()
        except Exception:  # an FMU that failed may refuse to terminate; free it all the same
            log.debug("FMU terminate failed", exc_info=True)
        try:
            self.fmu.freeInstance()
        except Exception:
            log.debug("FMU freeInstance failed", exc_info=True)
        self.c = None


def _free(live: list[_Slave]) -> None:
    """Free every instance in ``live`` (and empty it)."""
    for slave in live:
        slave.free()
    live.clear()


def _release(live: list[_Slave], folder: str) -> None:
    """The plant's end: its instances freed, its extracted FMU removed."""
    _free(live)
    shutil.rmtree(folder, ignore_errors=True)


class FmuPlant:
    """An FMI co-simulation FMU behind the :class:`~.plant.Plant` protocol (module docstring)."""

    def __init__(self, path: Path, fmap: FmuMap, ts_s: float) -> None:
        from fmpy import extract

        self.desc = check_fmu(path, fmap, "")
        self.fmap = fmap
        self.ts_s = ts_s
        step = self.desc.step_s
        self.substeps = max(1, math.ceil(ts_s / step - 1e-9)) if step is not None and step < ts_s else 1
        self._h = ts_s / self.substeps
        self.modelled_faults = fmap.faults
        folder = tempfile.mkdtemp(prefix="ehpss-fmu-")
        self._live: list[_Slave] = []
        self._finalizer = weakref.finalize(self, _release, self._live, folder)
        try:
            self._unzipdir = str(extract(str(path), folder))
        except Exception as exc:  # fmpy: plain Exceptions for bad member names
            self._finalizer()
            raise ConfigError("", "plant.path", f"cannot extract {path.name}: {one_line(str(exc))}") from exc
        refs = self.desc.refs
        self._out_keys = [k for k in OUTPUT_KEYS if k in refs]
        self._vr_current = (ctypes.c_uint * 1)(refs["current_a"])
        self._current = (ctypes.c_double * 1)()
        self._vr_out = (ctypes.c_uint * len(self._out_keys))(*(refs[k] for k in self._out_keys))
        self._out = (ctypes.c_double * len(self._out_keys))()
        self._fault_keys = [k for k in ACTUATOR_FAULTS if k in refs]
        self._vr_faults = (ctypes.c_uint * len(self._fault_keys))(*(refs[k] for k in self._fault_keys))
        self._fault_values = (ctypes.c_double * len(self._fault_keys))()
        self._slave: _Slave | None = None
        self._k = 0
        self.faults = FaultState()
        self._position_m = self._spool_m = self._load_pressure_pa = self._echo_a = 0.0
        self.reset()

    # ---- life cycle -------------------------------------------------------------------------
    def close(self) -> None:
        """Free the FMU instance and remove its extracted files (also done when collected)."""
        self._slave = None
        self._finalizer()

    def reset(self) -> None:
        """A fresh instance of the FMU, initialized at t = 0 with no current and no fault
        (ConfigError naming the FMU and the FMI status when it cannot be instantiated)."""
        if self._slave is not None and self._k == 0 and self.faults == FaultState():
            return  # fresh already
        _free(self._live)  # the extracted FMU stays; only the old instance goes
        self._k = 0
        self.faults = FaultState()
        self._echo_a = self._current[0] = 0.0
        try:
            slave = _Slave(self.desc, self._unzipdir)
            self._live.append(slave)
            slave.start()
            self._set_faults_on(slave)
            slave.set_real(self._vr_current, self._current, 1)
            slave.fmu.exitInitializationMode()
            self._read(slave)
        except Exception as exc:  # fmpy: FMICallException or a plain Exception (instantiate)
            raise ConfigError("", "plant.path", self._describe(exc, "initialization")) from exc
        self._slave = slave

    def _describe(self, exc: Exception, what: str) -> str:
        status = getattr(exc, "status", None)
        func = getattr(exc, "function", None)
        if status is not None and func is not None:
            return f"FMU {self.desc.name}: {func} returned {status_name(status)} ({what})"
        return f"FMU {self.desc.name}: {what} failed: {one_line(str(exc))}"

    def set_faults(self, faults: FaultState) -> None:
        """Apply new fault values from the next sample on (the mapped actuator faults go to the
        FMU now). ValueError for an actuator fault the map does not name: the scenario check
        (and the emulator's inject) refuse those before they get here."""
        for key in ACTUATOR_FAULTS:
            if key not in self.modelled_faults and getattr(faults, key) != 1.0:
                raise ValueError(f"FMU {self.desc.name} does not model {key} (no fmu_map.{key})")
        changed = [getattr(faults, k) != getattr(self.faults, k) for k in self._fault_keys]
        self.faults = faults
        if any(changed) and self._slave is not None:
            try:
                self._set_faults_on(self._slave)
                self._read(self._slave)  # outputs that feed a fault through (the actual spool)
            except (FMICallException, ctypes.ArgumentError) as exc:
                raise PlantStepError(self._describe(exc, f"setting faults at t = {self.t_s:.4f} s")) from exc

    def _set_faults_on(self, slave: _Slave) -> None:
        if self._fault_keys:
            for i, key in enumerate(self._fault_keys):
                self._fault_values[i] = getattr(self.faults, key)
            slave.set_real(self._vr_faults, self._fault_values, len(self._fault_keys))

    # ---- dynamics ---------------------------------------------------------------------------
    @property
    def t_s(self) -> float:
        """The FMU's time (s): samples stepped × Ts."""
        return self._k * self.ts_s

    def step(self, current_a: float) -> float:
        """Advance one sample with ``current_a`` held (limited by ``current_limit_a``); returns
        the applied current (A). PlantStepError when the FMU fails (module docstring)."""
        lim = self.faults.current_limit_a
        u = min(max(current_a, -lim), lim)
        slave = self._slave
        assert slave is not None
        t0 = self._k * self.ts_s
        h = self._h
        try:
            self._current[0] = u
            slave.set_real(self._vr_current, self._current, 1)
            for j in range(self.substeps):
                if not slave.do_step(t0 + j * h, h):
                    raise PlantStepError(
                        f"FMU {self.desc.name}: asked to terminate at t = {t0 + j * h:.4f} s"
                    )
            self._read(slave)
        except (FMICallException, ctypes.ArgumentError) as exc:  # the status; a bad value
            raise PlantStepError(self._describe(exc, f"step at t = {t0:.4f} s")) from exc
        self._k += 1
        return u

    def _read(self, slave: _Slave) -> None:
        out = self._out
        slave.get_real(self._vr_out, out, len(self._out_keys))
        pos, spool, p_l = out[0], out[1], out[2]
        if not (math.isfinite(pos) and math.isfinite(spool) and math.isfinite(p_l)):
            raise PlantStepError(
                f"FMU {self.desc.name}: non-finite output at t = {self.t_s:.4f} s "
                f"(position {pos}, spool {spool}, load pressure {p_l})"
            )
        self._position_m, self._spool_m, self._load_pressure_pa = pos, spool, p_l
        if len(self._out_keys) > 3:
            self._echo_a = out[3]

    # ---- sensors ----------------------------------------------------------------------------
    def outputs(self) -> tuple[float, float, float, float]:
        """``(position, actual spool, load pressure, current echo)`` (m, m, Pa, A): the
        properties below in one call (the emulation reads them every sample)."""
        return self._position_m, self._spool_m, self._load_pressure_pa, self.coil_current_a

    @property
    def position_m(self) -> float:
        """Piston position x (m), the FMU's output."""
        return self._position_m

    @property
    def spool_actual_m(self) -> float:
        """Actual spool displacement (m), the FMU's output."""
        return self._spool_m

    @property
    def spool_commanded_m(self) -> float:
        """Spool displacement before k_LOE (m): the actual spool / k_LOE when the FMU models
        k_LOE, else the actual spool."""
        k = self.faults.k_loe
        return self._spool_m / k if "k_loe" in self.modelled_faults and k > 0.0 else self._spool_m

    @property
    def load_pressure_pa(self) -> float:
        """Load pressure (Pa), the FMU's output."""
        return self._load_pressure_pa

    @property
    def coil_current_a(self) -> float:
        """Coil current echo (A): the FMU's ``current_echo_a`` output when mapped, else the
        current applied over the last sample."""
        return self._echo_a if len(self._out_keys) > 3 else self._current[0]
