"""gyro_sim.bench.compile_profile: each function's own time (its callees' taken out), LLVM's
share to the innermost compile."""
import time

from gyro_sim.bench.compile_profile import Profile

#: long enough for the process clock to tell the spans apart
SPIN = 0.05


def spin(seconds: float) -> None:
    end = time.process_time() + seconds
    while time.process_time() < end:
        pass


def test_a_callee_is_counted_once_and_llvm_goes_to_the_innermost():
    p = Profile(phase="x")
    p.start("caller")
    spin(SPIN)
    p.start("callee")
    p.llvm_start()
    spin(2 * SPIN)
    p.llvm_end()
    p.end()
    p.llvm_start()
    spin(SPIN)
    p.llvm_end()
    p.end()
    p.llvm_start()  # loading cached code: no compile
    spin(SPIN)
    p.llvm_end()
    by = {c.name: c for c in p.compiles}
    assert set(by) == {"caller", "callee"} and by["callee"].root == "caller" == by["caller"].root
    assert abs(by["callee"].cpu - 2 * SPIN) < SPIN / 2 and abs(by["callee"].llvm_cpu - 2 * SPIN) < SPIN / 2
    assert abs(by["caller"].cpu - 2 * SPIN) < SPIN / 2 and abs(by["caller"].llvm_cpu - SPIN) < SPIN / 2
    assert abs(p.outside_llvm_cpu - SPIN) < SPIN / 2
    assert "caller" in p.table() and "total: CPU" in p.table()
