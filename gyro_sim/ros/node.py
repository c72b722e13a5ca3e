"""Console script `gyro_sim_node`: the rclpy node `gyro_sim` and its main (docs/ros-interface.md).

    gyro_sim_node --ros-args --params-file config/params.yaml -p duration:=20.0

`GyroSimNode` is a thin class (the ROS 2 examples' style): parameters, publishers, the command
subscription, the services; everything physical happens in the physics thread
(gyro_sim.ros.loop) over the core's Simulator. main() checks the command line before rclpy
starts (--help, misspelt parameters), starts rclpy, the node and its physics thread, spins the
executor in this thread (commands, ~/reset, ~/pause) until the bounded run ends or
SIGINT/SIGTERM (see `Shutdown`), then closes the log and prints a summary and where the log is.

Exit status and the last line
-----------------------------
- 0: the run ended (its duration, a signal), the log (if any) complete: "log written: PATH (N
  records)", N the records the file holds (read back: the same count); publications dropped
  because the writer fell behind are counted on that line;
- 0: a signal during start-up (see `Shutdown`): one line, nothing run, no log file left;
- 2: bad input, nothing started: invalid parameters, a record path that exists (the check and
  the creation are one atomic step, gyro_sim.ros.recorder.create_log_file: of two nodes started
  on one path, one runs and the other gets this), or where no file can be created;
- 1: a fault mid-work: a simulation error, the physics thread or executor failing, out of
  memory (or of threads) anywhere in start-up or the run (one line; a log being written is
  closed), or the recording failing. Recording failures (the writer process died, a write
  failed: no space left on the device, a file-size limit) are seen at once: one console line,
  the ``record`` key of the run's /diagnostics status, an event; the run then *stops* (rather
  than go on with a log missing part of the run: the log's promises, every command received
  and the re-simulation contract, would not hold), and the last line says "log incomplete:
  FILE: why" and how ``gyro-sim recover`` reads back what was written before (never "log
  written").
"""
from __future__ import annotations

import os

# One BLAS thread: the chain's matrices are small and a threaded BLAS fights the loop (cli.py).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import dataclasses
import json
import signal
import sys
import threading
import time

try:  # rclpy from ROS 2 Jazzy (pip install 'gyro_sim[ros]'); --help works without it
    from rcl_interfaces.msg import ParameterDescriptor, ParameterType
    from rclpy.node import Node
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from std_srvs.srv import SetBool, Trigger

    ROS_IMPORT_ERROR = None
except ImportError as _exc:  # the class below is then never instantiated
    Node = object
    ROS_IMPORT_ERROR = _exc

from gyro_sim.simulator import Simulator
from gyro_sim.msgs.messages import decode_axis_moments, decode_joint_command
from gyro_sim.ros.loop import Pause, Reset, SimLoop, warm_up
from gyro_sim.ros.outputs import Outputs, node_topics
from gyro_sim.ros.pacing import ShareLimit
from gyro_sim.ros.params import PARAMETERS, ParameterError, validate
from gyro_sim.ros import start_signal_line

#: bytes in a megabyte (record_queue_mb)
MEGABYTE = 1 << 20
#: messages of the RuntimeError raised when a thread cannot be started (out of memory or of
#: processes: Python's threading, rclpy's executor)
THREAD_START_ERRORS = ("can't start new thread", "pthread_create failed", "Resource temporarily unavailable")
#: what the dynamic loader says when a shared library does not fit in the address space left
LOAD_MEMORY_ERRORS = ("failed to map segment from shared object", "Cannot allocate memory",
                      "cannot allocate memory")
#: room (bytes of address space) that loading scipy's LAPACK needs (`load_lapack`): measured,
#: a process with 96 MB of room under its limit loads it, with 40-48 MB its OpenBLAS spins
#: forever, with less the loader refuses
LAPACK_ROOM = 128 << 20
#: address space (bytes) a start needs beyond what the process has mapped when main begins
#: (`check_address_space`). Measured (hinge chain, recording, 2 cores): ~300 MB mapped then;
#: rclpy's node creation alone needs ~120 MB more once the kernels are loaded (with ~20 MB
#: Fast DDS waits forever for a logging thread it could not start; with 40-100 MB it aborts or
#: crashes); a whole start ran under limits of 1100 MB and failed (threads, libraries) at 1000 MB
START_ROOM = 640 << 20

#: a start on a cold cache steps on the numpy reference while its kernels compile in the
#: background (gyro_sim.warmup.start_deferred) where one physics step on numpy takes at most this
#: share of the step (the rest: publications, commands, the executor); else it compiles first
NUMPY_STEP_SHARE = 0.9
#: physics steps timed on the numpy reference to decide it (their median; after one untimed)
NUMPY_TIMED_STEPS = 20

#: GIL switch interval (s) while the node runs: bounds how long the physics thread, woken at
#: its deadline or back from a publish (which releases the interpreter), waits for the executor
#: thread (Python's default is 5 ms). With a controller answering every publication at 1 kHz
#: (`gyro-sim bench loop --rates 1000 --modes realtime`, three pairs of runs in turn, 2 cores),
#: 0.1 ms against 0.5 ms: command latency p99 1807 / 1395 / 776 us against 7277 / 3450 / 1190 us,
#: deadline misses 296 / 83 / 38 against 977 / 368 / 116
SWITCH_INTERVAL = 1e-4
#: longest wait (s) for the physics thread to say how it is scheduled (it does so first thing)
STARTED_TIMEOUT = 1.0
#: longest wait of the executor (s): how soon a signal is acted on
SPIN_PERIOD = 0.1
#: the largest share of the interpreter the executor thread takes on average while callbacks
#: keep coming (gyro_sim.ros.pacing.ShareLimit): beyond, it sleeps, leaving the interpreter to
#: the physics thread, so a flood of commands cannot starve the physics loop
EXECUTOR_SHARE = 0.2
#: CPU seconds the executor may run beyond its share before it sleeps: commands at a steady
#: 1 kHz are taken as they come (a sleep after each one let the subscription's queue overflow)
EXECUTOR_BURST = 0.005


def descriptor(p) -> ParameterDescriptor:
    """The descriptor of a parameter of gyro_sim.ros.params.PARAMETERS (read-only: set at start)."""
    kinds = {float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING,
             bool: ParameterType.PARAMETER_BOOL}
    d = ParameterDescriptor(name=p.name, type=kinds[p.kind], description=p.description, read_only=True)
    if p.kind is float:
        # integers are accepted too (-p duration:=10): the type and range are checked by validate()
        d.dynamic_typing = True
        d.additional_constraints = f"a number in [{p.low:g}, {p.high:g}]"
    return d


def numpy_step_cost(sim, dt: float, steps: int = NUMPY_TIMED_STEPS) -> float:
    """The median CPU time (s) of this thread for one physics step of `dt` of `sim`, from
    `steps` timed after one untimed; `sim` is reset after. CPU time, not wall time: what the
    step costs, not how much of the processor other processes take at this moment (the physics
    thread runs at a real-time priority where it may)."""
    sim.advance(dt)
    times = []
    for _ in range(steps):
        t0 = time.thread_time()
        sim.advance(dt)
        times.append(time.thread_time() - t0)
    sim.reset()
    return sorted(times)[len(times) // 2]


def log_params(sim, cfg, topics=None) -> dict:
    """The log's run parameters: the re-simulation contract of gyro_sim.log.record (one advance of
    1/physics_rate per step), plus the node's own parameters and names (`topics`: its
    gyro_sim.msgs.messages.TopicNames; default the root namespace's)."""
    from gyro_sim.log.record import run_params
    from gyro_sim.msgs.messages import ROOT_TOPICS

    topics = topics or ROOT_TOPICS
    own = {k: v for k, v in cfg.as_dict().items() if k not in ("publish_rate", "duration")}
    # dynamics: the backend the run starts on (numpy while its kernels compile: the switch is an
    # event, gyro_sim.log.resim.DYNAMICS_EVENT)
    return run_params(sim, advance_dt=cfg.dt, publish_rate=cfg.publish_rate, source="gyro_sim_node",
                      duration=cfg.duration or None, commands_topic=topics.axis_moments,
                      namespace=topics.namespace, node=topics.node, dynamics=sim.backend, **own)


def method_choice(sim, cfg) -> str:
    """What "fixed" steps with at the start and why, for the start line ("" for other methods)."""
    if cfg.integrator != "fixed":
        return ""
    from gyro_sim.integrators.fixed import fixed_step_method

    return fixed_step_method(sim, cfg.dt)[1]


def stiffness_note(sim, cfg) -> str:
    """A warning when the explicit fixed-step method runs a scene too stiff for its step
    (gyro_sim.integrators.fixed: h |lambda| at the initial state against RK4's limit)."""
    if cfg.integrator not in ("rk4", "lie4"):
        return ""
    from gyro_sim.integrators.fixed import fixed_step_choice

    c = fixed_step_choice(sim, cfg.dt)
    if c.method == "rk4" and c.substeps == 1:
        return ""
    return (f"the scene is stiff for {cfg.integrator} at physics_rate {cfg.physics_rate:g} Hz ({c.reason}); "
            f"it may stop with a simulation error or drift: raise physics_rate or try -p integrator:=fixed")


class GyroSimNode(Node):
    """The simulation node. Raises ParameterError (nothing created) on invalid parameters."""

    def __init__(self):
        super().__init__("gyro_sim")
        values, problems = {}, []
        for p in PARAMETERS:
            try:
                values[p.name] = self.declare_parameter(p.name, p.default, descriptor(p)).value
            except Exception as exc:  # noqa: BLE001 - rclpy's type and range exceptions
                problems.append(f"{p.name}: {exc}")
        if problems:
            raise ParameterError("\n".join(problems))
        self.config = cfg = validate(values)
        self.topics = topics = dataclasses.replace(node_topics(self), frame_prefix=cfg.frame_prefix)
        self.recorder = None
        log_file = None
        if cfg.record:  # created now, atomically (OutputError if it exists or cannot be): nothing run yet
            from gyro_sim.ros.recorder import create_log_file

            log_file = create_log_file(cfg.record, cfg.overwrite, what="record")
        from gyro_sim import warmup

        try:
            # a cold cache: the numpy reference until the kernels compiled in the background are loaded
            self.sim = Simulator(cfg.scene, integrator=cfg.integrator, rtol=cfg.rtol, atol=cfg.atol, step=cfg.dt,
                                 backend="numpy" if warmup.deferred() else cfg.backend)
            if warmup.deferred():
                self._numpy_or_compiled(cfg)
            if log_file is not None:
                from gyro_sim.ros.recorder import LiveRecorder

                self.recorder = LiveRecorder(cfg.record, scene=cfg.scene, params=log_params(self.sim, cfg, topics),
                                             log_file=log_file, topics=topics,
                                             max_backlog_bytes=int(cfg.record_queue_mb * MEGABYTE))
            self.outputs = Outputs(self, self.sim, cfg, self.recorder, topics=topics)
            demo = None
            if cfg.demo and self.sim.axis_names:
                from gyro_sim.ros.demo import Demo

                demo = Demo.for_scene(self.sim, cfg.dt)
            warm_up(self.sim, cfg.dt)  # every path the loop takes, run once: its first steps pay for none
            self.loop = SimLoop(self.sim, cfg, self.outputs, demo=demo)
            if warmup.deferred():
                warmup.load_when_compiled(self.sim, self.loop.promote)
            self.outputs.publish_robot_description()
        except BaseException:  # nothing recorded yet: the file created is removed
            if self.recorder is not None:
                self.recorder.abandon()
            elif log_file is not None:
                log_file.abandon()
            raise
        self.create_subscription(Float64MultiArray, "~/axis_moments", self.on_command, 10, raw=True)
        if self.sim.control_names:
            self.create_subscription(JointState, "~/joint_commands", self.on_joint_command, 10, raw=True)
        self.create_service(Trigger, "~/reset", self.on_reset)
        self.create_service(SetBool, "~/pause", self.on_pause)
        self.get_logger().info(
            f"scene '{cfg.scene.name}' ({cfg.scene_path}); axes {self.sim.axis_names}; "
            f"physics {cfg.physics_rate:g} Hz ({self.sim.integrator_name}"
            + (f" = {choice}" if (choice := method_choice(self.sim, cfg)) else "")
            + f", {self.sim.backend} dynamics), "
            f"publish {cfg.publish_rate:g} Hz, "
            + (f"lock-step: one period of {cfg.steps_per_publish} steps per command on ~/axis_moments"
               + (" or ~/joint_commands" if self.sim.control_names else "") + ", "
               "waiting for the first" if cfg.lockstep else
               f"real-time factor {cfg.real_time_factor:g}, {self.loop.pacing.per_chunk} steps per wake-up"
               + ("; holding the initial state until the first command" if cfg.hold == "until_command" else ""))
            + (f"; recording to {cfg.record}" if cfg.record else "")
        )
        if demo is not None:
            self.get_logger().info(demo.describe(self.sim.axis_names))
        elif cfg.demo:
            self.get_logger().warning("demo: the scene has no actuated axes, nothing to drive")
        self.stiffness_note = stiffness_note(self.sim, cfg)
        if self.stiffness_note:
            self.get_logger().warning(self.stiffness_note)

    def _numpy_or_compiled(self, cfg) -> None:
        """Keep the numpy Simulator if a physics step on it fits NUMPY_STEP_SHARE of the step;
        else say so in one line and compile the kernels now, before real time (as without a
        background compile), and step on them from the start."""
        from gyro_sim import warmup

        cost = numpy_step_cost(self.sim, cfg.dt)
        if cost <= NUMPY_STEP_SHARE * cfg.dt:
            return
        warmup.stop_deferring()
        print(f"gyro_sim_node: a physics step takes {cost * 1e6:.0f} us on the numpy reference, more than "
              f"{NUMPY_STEP_SHARE:.0%} of the {cfg.dt * 1e3:g} ms step: compiling the kernels before real time "
              "instead", file=sys.stderr, flush=True)
        warmup.precompile(sys.stderr, prog="gyro_sim_node", integrator=cfg.integrator, helper=False)
        self.sim = Simulator(cfg.scene, integrator=cfg.integrator, rtol=cfg.rtol, atol=cfg.atol, step=cfg.dt,
                             backend=cfg.backend)

    def on_command(self, raw: bytes) -> None:
        """Bounded work: decode (no rclpy message objects), check, keep as the latest."""
        try:
            values = decode_axis_moments(raw)
        except ValueError:  # malformed bytes: refused like a NaN
            values = [float("nan")]
        reason = self.loop.submit_command(bytes(raw), values)
        if reason:
            self.get_logger().warning(
                f"command rejected ({reason}); axes: {self.sim.axis_names}; "
                f"{self.loop.commands.counters.rejected} rejected so far", throttle_duration_sec=2.0)

    def on_joint_command(self, raw: bytes) -> None:
        """Bounded work: decode (no rclpy message objects), map onto the servos' controls, keep."""
        try:
            command = decode_joint_command(raw)
        except ValueError:  # malformed bytes: refused
            command = None
        reason = self.loop.submit_joint_command(bytes(raw), command)
        if reason:
            self.get_logger().warning(
                f"joint command rejected ({reason}); servos: {self.sim.control_names}; "
                f"{self.loop.commands.counters.rejected} rejected so far", throttle_duration_sec=2.0)

    def on_reset(self, request, response):
        response.success, response.message = self.loop.request(Reset())
        return response

    def on_pause(self, request, response):
        response.success, response.message = self.loop.request(Pause(bool(request.data)))
        return response

    def finish(self) -> dict:
        """Stop the loop, close the log; the run's statistics."""
        self.loop.stop()
        stats = self.loop.summary()
        rec = self.recorder
        if rec is not None:
            rec.close()
            stats.update(record=rec.path, record_file=rec.file, record_complete=rec.complete,
                         record_failure=rec.failure, records_written=rec.written,
                         records_in_file=rec.records_in_file, records_handed=rec.handed,
                         records_dropped=rec.dropped_records, publications_dropped=rec.dropped_publications,
                         recorder_max_backlog=rec.max_backlog, recorder_max_backlog_bytes=rec.max_backlog_bytes_seen,
                         recorder_thread_cpu_s=rec.thread_cpu, recorder_error=rec.error,
                         recorder_sender_cpu_s=rec.sender_cpu, recorder_open_cpu_s=rec.open_cpu)
        return stats

    def close_log(self) -> None:
        """Close the log if `finish` did not (an error on the way out)."""
        if self.recorder is not None:
            self.recorder.close()


class Shutdown:
    """SIGINT and SIGTERM handling owned by the node, not by rclpy.

    During start-up (from main's first line until the physics thread is about to start: the
    first numba compile, rclpy's start, the scene load, the recorder's start, the warm-up) a
    signal gives the start up at once: one line ("SIGTERM during start-up: not started"), the
    recorder's writer process killed and the log file created for it removed (nothing was
    recorded: no file is left that could be taken for a log), exit status 0, within a
    fraction of a second even in the middle of a compile. It is done by a thread woken by the
    signal itself (``signal.set_wakeup_fd``), not by the Python handler, which runs only
    between two bytecodes of the main thread (never during a long call into compiled code).

    Afterwards a signal only sets `requested`: rclpy's own handlers shut the context down from
    inside the signal, which races with the executor's wait ("failed to initialize wait set:
    the given context is not valid") and can leave the log unclosed. Here the main loop sees
    the flag within one spin period, stops the physics thread, closes the log, and only then
    shuts rclpy down.
    """

    def __init__(self):
        self.requested = threading.Event()
        self.starting = True
        self.signal_name = ""
        self._lock = threading.Lock()
        self._giving_up = False
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._handle)
        self._wakeup: tuple[int, int] | None = None
        try:
            r, w = os.pipe()
            os.set_blocking(w, False)
            signal.set_wakeup_fd(w, warn_on_full_buffer=False)
            self._wakeup = (r, w)
            threading.Thread(target=self._watch, name="gyro_sim-start-signals", daemon=True).start()
        except (OSError, ValueError, RuntimeError):  # no watcher: the Python handler gives up the start itself
            self._restore_wakeup()

    def _restore_wakeup(self) -> None:
        if self._wakeup is not None:
            try:
                signal.set_wakeup_fd(-1)
            except ValueError:  # not the main thread
                pass
            for fd in self._wakeup:
                os.close(fd)
            self._wakeup = None

    def _handle(self, signum, frame) -> None:
        self.signal_name = signal.Signals(signum).name
        self.requested.set()
        if self.starting and self._wakeup is None:
            self._give_up_start(signum)

    def _watch(self) -> None:
        """Woken by every signal during start-up (the wakeup fd gets its number)."""
        r = self._wakeup[0]
        while self.starting:
            try:
                data = os.read(r, 64)
            except OSError:
                return
            for signum in data:
                if signum in (signal.SIGINT, signal.SIGTERM):
                    self._give_up_start(signum)

    def _give_up_start(self, signum: int) -> None:
        with self._lock:
            if not self.starting or self._giving_up:
                return
            self._giving_up = True
        name = signal.Signals(signum).name
        recorder = sys.modules.get(f"{__package__}.recorder")
        if recorder is not None:
            recorder.abandon_all()
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os.write(2, (start_signal_line(name) + "\n").encode())
        os._exit(0)

    def hold_if_giving_up(self) -> None:
        """A start being given up is ended by the thread doing it (its one line, exit 0): the
        main thread, which the give-up may have broken (its writer killed), waits for that."""
        if self._giving_up:
            threading.Event().wait()

    def start_done(self) -> None:
        """The start-up is over: from now on a signal only sets `requested` (main thread only).
        If a signal is giving the start up at this very moment, its thread ends the process."""
        with self._lock:
            giving_up = self._giving_up
            if not giving_up:
                self.starting = False
        if giving_up:
            threading.Event().wait()  # the watcher thread ends the process
        if self._wakeup is not None:
            try:
                os.write(self._wakeup[1], b"\0")  # wake the watcher: it ends
            except OSError:
                pass
            try:
                signal.set_wakeup_fd(-1)
            except ValueError:
                pass


def _address_space_room() -> int | None:
    """Bytes of address space left under the soft RLIMIT_AS (None: no limit, or unknown)."""
    import resource

    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    try:
        with open("/proc/self/status") as f:
            size = next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmSize:"))
    except (OSError, StopIteration, ValueError):
        return None
    return soft - size


def check_address_space() -> None:
    """Under an address-space limit (prlimit --as) too tight for a start, MemoryError at once.

    Below it, starts failed anywhere, mostly inside compiled libraries where no Python error
    can be raised (aborts, crashes) and twice by hanging for good with the interpreter lock
    held (Fast DDS, OpenBLAS), where neither a signal nor any thread can end the process. With
    START_ROOM of room, none of those was met; above it, what is still raised is said in one
    line (`resource_error`)."""
    room = _address_space_room()
    if room is not None and room < START_ROOM:
        raise MemoryError(f"the address-space limit leaves {room >> 20} MB, a start needs about "
                          f"{START_ROOM >> 20} MB more")


def load_lapack() -> None:
    """Under an address-space limit (prlimit --as), load scipy's LAPACK now, checked.

    numba's compiled LAPACK calls (the radau kernels, which gyro_sim.warmup loads with every
    kernel) load it; its OpenBLAS, when it cannot allocate its work buffers, retries forever
    while holding the interpreter lock, so that neither a signal handler nor any thread runs
    again: the node hung. With less than LAPACK_ROOM left, MemoryError instead. Without a limit
    nothing is done here."""
    room = _address_space_room()
    if room is None or "scipy.linalg.cython_lapack" in sys.modules:
        return
    if room < LAPACK_ROOM:
        raise MemoryError(f"{room >> 20} MB of address space left under the limit, scipy's LAPACK needs "
                          f"{LAPACK_ROOM >> 20} MB to load")
    try:
        import scipy.linalg.cython_lapack  # noqa: F401
    except ImportError:  # no scipy, or a library that did not fit: numba says so where it is needed
        pass


def resource_error(exc: BaseException) -> str | None:
    """One line for running out of memory or of threads, whatever raised it (the exception or
    one it was raised from); None for anything else (a bug keeps its traceback)."""
    import errno

    seen = set()
    e: BaseException | None = exc
    while e is not None and id(e) not in seen:
        seen.add(id(e))
        text = str(e).splitlines()[0] if str(e) else ""
        if isinstance(e, MemoryError):
            return f"out of memory (MemoryError{': ' + text if text else ''})"
        if isinstance(e, OSError) and e.errno == errno.ENOMEM:
            return f"out of memory ({text})"
        if any(m in text for m in THREAD_START_ERRORS):
            return f"cannot start a thread ({text}): out of memory or of processes"
        if any(m in str(e) for m in LOAD_MEMORY_ERRORS):
            return f"out of memory: a library could not be loaded ({text[:200]})"
        e = e.__cause__ or e.__context__
    room = _address_space_room()
    if room is not None and isinstance(exc, (SystemError, ImportError, OSError)):
        # what CPython and the loader raise when an allocation fails inside an import
        import resource

        limit = resource.getrlimit(resource.RLIMIT_AS)[0]
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        return f"failed under the address-space limit of {limit >> 20} MB, probably out of memory ({text[:200]})"
    return None


def main(argv=None) -> int:
    shutdown = Shutdown()
    try:
        code = _main(argv, shutdown)
        shutdown.hold_if_giving_up()
        return code
    except BaseException as exc:  # only resources are said in one line; bugs keep their traceback
        shutdown.hold_if_giving_up()
        why = resource_error(exc)
        if why is None:
            raise
        print(f"gyro_sim_node: {why}; stopped", file=sys.stderr)
        return 1


def _main(argv, shutdown: Shutdown) -> int:
    from gyro_sim.dynamics.actuators import ActuatorError
    from gyro_sim.safe_paths import OutputError
    from gyro_sim.ros.params import preflight

    # --help, misspelt parameters and the first numba compile, before rclpy starts
    check_address_space()
    load_lapack()
    code = preflight(sys.argv if argv is None else argv)
    if code is not None:
        return code
    if ROS_IMPORT_ERROR is not None:
        print(f"gyro_sim_node needs ROS 2 Jazzy's rclpy (pip install 'gyro_sim[ros]'): {ROS_IMPORT_ERROR}",
              file=sys.stderr)
        return 2
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from gyro_sim.ros.discovery import announce_often

    announce_often()
    try:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:  # rcl's argument errors (a missing --params-file ...)
        if resource_error(exc) is not None:
            raise
        print(f"gyro_sim_node: bad arguments: {exc}".splitlines()[0], file=sys.stderr)
        return 2
    node = None
    try:
        try:
            node = GyroSimNode()
        except (ParameterError, OutputError, ActuatorError) as exc:  # one line for one problem, one more per other
            sep = " " if "\n" not in str(exc) else "\n  "
            print("gyro_sim_node: invalid parameters, nothing started:" + sep + str(exc).replace("\n", "\n  "),
                  file=sys.stderr)
            return 2
        except Exception as exc:  # the log writer could not start (no space left...)
            from gyro_sim.ros.recorder import RecordingError

            if not isinstance(exc, RecordingError):
                raise
            print(f"gyro_sim_node: record: the log writer could not start: {exc}; nothing started", file=sys.stderr)
            return 1
        sys.setswitchinterval(SWITCH_INTERVAL)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        share = ShareLimit(EXECUTOR_SHARE, EXECUTOR_BURST)
        spin_error = None
        try:
            shutdown.start_done()
            if not shutdown.requested.is_set():
                node.loop.start()
                if node.loop.started.wait(STARTED_TIMEOUT):  # how the physics thread is scheduled
                    log = node.get_logger().info if node.loop.pacing.priority or not node.config.thread_priority \
                        or node.config.real_time_factor <= 0 or node.config.lockstep else node.get_logger().warning
                    log(f"physics thread: {node.loop.pacing.scheduling}")
            while not shutdown.requested.is_set() and not node.loop.finished.is_set():
                if node.loop.thread.ident is not None and not node.loop.thread.is_alive():
                    break  # never without `finished`; a guard: nothing here waits on a dead thread
                t0 = time.thread_time()
                executor.spin_once(timeout_sec=SPIN_PERIOD)
                pause = share.after(time.thread_time() - t0)  # its CPU, not the wait for a callback
                if pause > 0.0:
                    time.sleep(pause)
        except Exception as exc:  # noqa: BLE001 - the log is closed below whatever happened
            why = resource_error(exc)
            spin_error = why or f"{type(exc).__name__}: {exc}"
        stats = node.finish()
        _report(node, stats, shutdown.signal_name)
        code = 0
        if node.loop.out_of_memory:
            print("gyro_sim_node: the physics loop failed: out of memory (MemoryError)", file=sys.stderr)
            code = 1
        elif node.loop.crash:
            print(f"gyro_sim_node: the physics loop failed:\n{node.loop.crash}", file=sys.stderr)
            code = 1
        if spin_error:
            print(f"gyro_sim_node: the executor failed: {spin_error}", file=sys.stderr)
            code = 1
        if node.recorder is not None and not node.recorder.complete:
            code = 1  # said by _report
        if node.loop.failure is not None:
            print(f"gyro_sim_node: simulation error: {node.loop.failure}", file=sys.stderr)
            code = 1
        return code
    finally:
        if node is not None:
            try:
                node.close_log()
            finally:
                node.destroy_node()
        rclpy.try_shutdown()


def _summary_line(stats: dict, cfg) -> None:
    target = (f"lock-step, {stats['commands_per_wall_s']:.0f} commands per wall second" if cfg.lockstep
              else f"target {cfg.real_time_factor:g}")
    print(
        f"gyro_sim_node: simulated {stats['node_time_s']:.3f} s in {stats['wall_s']:.3f} s wall "
        f"(real-time factor {stats['real_time_factor_achieved']:.3f}, {target}), "
        f"step time p50 {stats['step_time_p50_us']:.0f} us / p99 {stats['step_time_p99_us']:.0f} us, "
        f"{stats['deadline_misses']} deadline misses, CPU {100 * stats['cpu_share']:.0f} %"
    )


def _report(node, stats: dict, signal_name: str = "") -> None:
    cfg = node.config
    if signal_name:
        print(f"gyro_sim_node: {signal_name}: stopped at node time {stats['node_time_s']:.3f} s")
    if stats["wall_s"] == 0.0:
        print("gyro_sim_node: stopped during start-up, nothing simulated")
    else:
        _summary_line(stats, cfg)
    if cfg.stats_file:
        try:
            with open(cfg.stats_file, "w") as f:
                json.dump(stats, f, indent=1, default=str)
        except OSError as exc:
            print(f"gyro_sim_node: stats_file {cfg.stats_file}: {exc.strerror or exc}", file=sys.stderr)
    rec = node.recorder
    if rec is not None and rec.complete:
        dropped = (f"; {rec.dropped_records} records of {rec.dropped_publications} publications dropped: the log "
                   f"writer fell behind" if rec.dropped_records else "")
        print(f"gyro_sim_node: log written: {rec.file} ({rec.records_in_file} records{dropped})")
        print(f"  view it:  rerun {rec.file}")
        print(f"       or:  gyro-sim view {rec.file}")
    elif rec is not None:
        sys.stdout.flush()
        print(f"gyro_sim_node: log incomplete: {rec.file}: {rec.failure or rec.error}; what was written before "
              f"can be read back with `gyro-sim recover {rec.file} -o fixed.mcap`", file=sys.stderr)
    sys.stdout.flush()


if __name__ == "__main__":
    sys.exit(main())
