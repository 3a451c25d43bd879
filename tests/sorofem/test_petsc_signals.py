"""The FEM layer leaves Python's signal handling alone (sorofem._petsc): PETSc starts without its handlers."""
import subprocess
import sys
import textwrap

PIPE = textwrap.dedent("""
    import socket
    import sorofem.fem  # noqa: F401  (PETSc and DOLFINx loaded)
    a, b = socket.socketpair()
    b.close()
    try:
        a.sendall(b"x" * 100)
        a.sendall(b"x" * 100)
    except BrokenPipeError:
        print("BrokenPipeError")
""")

CRASH = textwrap.dedent("""
    import ctypes, faulthandler
    faulthandler.enable()
    import sorofem.mesh  # noqa: F401
    def crash_here():
        ctypes.string_at(0)
    crash_here()
""")


def test_a_write_to_a_closed_socket_raises_instead_of_aborting_the_process(subprocess_env):
    """Without the fix PETSc's SIGPIPE handler killed the process (MPI_Abort, exit 59): a board client whose
    board had dropped the connection took the whole test run down."""
    env = {k: v for k, v in subprocess_env.items() if k != "PETSC_OPTIONS"}
    res = subprocess.run([sys.executable, "-c", PIPE], capture_output=True, text=True, env=env, timeout=120)
    assert res.returncode == 0 and res.stdout.strip() == "BrokenPipeError", (res.returncode, res.stderr[-500:])


def test_a_native_crash_prints_the_python_stack(subprocess_env):
    env = {k: v for k, v in subprocess_env.items() if k != "PETSC_OPTIONS"}
    res = subprocess.run([sys.executable, "-c", CRASH], capture_output=True, text=True, env=env, timeout=120)
    assert res.returncode == -11, res.returncode                 # SIGSEGV, not PETSc's MPI_Abort (59)
    assert "Fatal Python error: Segmentation fault" in res.stderr and "crash_here" in res.stderr
    assert "PETSC ERROR" not in res.stderr
