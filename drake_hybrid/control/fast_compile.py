"""numba's compile of the fast law (control/fast_law.py), kept off the critical path.

The kernels take numba 30-65 s to compile on 2 cores, once per machine (numba's ``cache=True`` keeps
the machine code on disk; a new constraint's generated module about 1.5 s). A controller whose
compiled law is not on disk yet does not wait for it: at its first tick ``FastLaw`` hands the
signatures of that tick's calls (their numba types) to one compile job in a background process
(``python -m drake_hybrid.control.fast_compile``) and runs the generic law (control/law.py, the
same law: equal to 1e-12, tests/test_fast_law.py) for its whole life, so a run's results never
depend on when the job finishes. Controllers built after the job has finished (the next run, the
next sweep point, another Dask worker on the machine) load the compiled law from the cache in a
fraction of a second.

What is compiled is recorded per function and signature in ``cache_folder()/compiled`` (a file
per entry, written by the job once numba has saved its cache); an entry's key holds the
function's source (its file's size and modification time, which numba's cache index checks too),
the numba version and ``NUMBA_CACHE_DIR``. One job runs at a time per machine
(``compiling.lock``, taken over from a process that died); its output goes to ``compile.log``, and
a job that fails leaves ``failed`` with the error: the controllers then warn once and keep the
generic law. ``DRAKE_HYBRID_COMPILE=foreground`` (or ``set_policy("foreground")``) compiles at the
first tick in the process instead, as benchmarks and the compiled law's own tests need.
"""

import contextlib
import hashlib
import importlib.util
import os
import pickle
import subprocess
import sys
import time
from pathlib import Path

from drake_hybrid.control import fast_kernels
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.locks import process_alive

POLICIES = ("background", "foreground")
_POLICY = [os.environ.get("DRAKE_HYBRID_COMPILE", "background")]


def cache_folder():
    """Where the generated constraint modules, the compiled entries and the job's files live."""
    return Path(os.environ.get("DRAKE_HYBRID_CACHE", Path.home() / ".cache" / "drake_hybrid")) / "fast_law"


def policy():
    """"background" (the default) or "foreground": how a controller gets a law that is not compiled yet."""
    if _POLICY[0] not in POLICIES:
        raise ConfigError(f"DRAKE_HYBRID_COMPILE must be one of {', '.join(POLICIES)}, got '{_POLICY[0]}'")
    return _POLICY[0]


def set_policy(value):
    """Set ``policy()`` for this process (returns the previous one)."""
    if value not in POLICIES:
        raise ConfigError(f"compile policy must be one of {', '.join(POLICIES)}, got '{value}'")
    previous, _POLICY[0] = _POLICY[0], value
    return previous


@contextlib.contextmanager
def foreground():
    """``policy()`` "foreground" inside the block (restored after it): every controller built in it runs
    the compiled law, compiled at its first tick where the machine has none yet. For results that must
    not depend on when a background compile finished (a sweep's points: the sampled loop's central
    differences see the two laws' 1e-12 differences at 1e-7)."""
    previous = set_policy("foreground")
    try:
        yield
    finally:
        set_policy(previous)


def entry_key(function, signature):
    """The identity of one compiled entry: ``function`` (a numba dispatcher) at ``signature`` (a tuple of
    numba types), with what decides whether numba's cache of it is valid here."""
    import numba  # optional: fast_kernels.NUMBA_ERROR says when it is missing

    source = Path(function.py_func.__code__.co_filename)
    stat = source.stat()
    parts = [str(source.resolve()), function.py_func.__qualname__, str(stat.st_size), str(stat.st_mtime_ns),
             repr(tuple(signature)), numba.__version__, os.environ.get("NUMBA_CACHE_DIR", "")]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:32]


def _entry_path(key):
    return cache_folder() / "compiled" / f"{key}.ok"


def compiled(calls):
    """True if every (function, signature) of ``calls`` is in numba's cache (recorded by a job or a
    foreground compile)."""
    return all(_entry_path(entry_key(function, signature)).exists() for function, signature in calls)


def record(calls):
    """Record ``calls`` as compiled (after numba has cached them)."""
    for function, signature in calls:
        path = _entry_path(entry_key(function, signature))
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(f"{function.py_func.__qualname__}{tuple(signature)}\n")


def failure():
    """The error text of the last failed job, or None."""
    path = cache_folder() / "failed"
    return path.read_text().strip() if path.exists() else None


def signature_of(arguments):
    """The numba types of a call's ``arguments`` (what its dispatcher compiles for)."""
    import numba

    return tuple(numba.typeof(argument) for argument in arguments)


def job_running():
    """The process id of the running compile job, or None."""
    try:
        pid = int((cache_folder() / "compiling.lock").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return None
    return pid if process_alive(pid) else None


def start_job(calls, module_path=None):
    """Start the background compile of ``calls`` ([(dispatcher, signature)]: kernels of fast_kernels,
    or functions of the generated module at ``module_path``) unless a job is running. Returns the
    job's process id (the running one's if there is one), or None when no job could start."""
    running = job_running()
    if running is not None:
        return running
    folder = cache_folder()
    folder.mkdir(parents=True, exist_ok=True)
    lock = folder / "compiling.lock"
    lock.unlink(missing_ok=True)                  # a lock whose process died (job_running found none alive)
    try:
        descriptor = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:                       # another process started one just now
        return job_running()
    os.write(descriptor, f"{os.getpid()}\n".encode())     # held by this process until the job's id replaces it
    request = folder / f"request-{os.getpid()}-{time.monotonic_ns()}.pickle"
    entries = [(function.py_func.__module__, function.py_func.__name__, tuple(signature))
               for function, signature in calls]
    request.write_bytes(pickle.dumps({"module_path": str(module_path) if module_path else None, "calls": entries}))
    with open(folder / "compile.log", "ab") as log:
        process = subprocess.Popen([sys.executable, "-m", "drake_hybrid.control.fast_compile", str(request)],
                                   stdin=subprocess.DEVNULL, stdout=log, stderr=log, start_new_session=True,
                                   env=dict(os.environ, DRAKE_HYBRID_COMPILE="foreground"))
    os.lseek(descriptor, 0, os.SEEK_SET)
    os.write(descriptor, f"{process.pid:<12d}\n".encode())
    os.close(descriptor)
    return process.pid


def import_file(path):
    """The module of the Python file at ``path`` (a generated constraint module), imported once per process
    under its file's name."""
    name = Path(path).stem
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    sys.modules[name] = module
    return module


def run_job(request_path):
    """The job: compile every call of the request (numba saves each to its cache), record them, release
    the lock. A failure is written to ``failed`` (and the job's log). It yields the CPU to the run
    that started it (a lower priority, ``os.nice``): that run uses the generic law meanwhile."""
    os.nice(10)
    folder = cache_folder()
    try:
        request = pickle.loads(Path(request_path).read_bytes())
        generated = import_file(request["module_path"]) if request["module_path"] else None
        calls = []
        for module_name, name, signature in request["calls"]:
            owner = fast_kernels if module_name == fast_kernels.__name__ else generated
            function = getattr(owner, name)
            start = time.perf_counter()
            function.compile(signature)
            print(f"compiled {module_name}.{name}{signature} in {time.perf_counter() - start:.1f} s", flush=True)
            calls.append((function, signature))
        record(calls)
        (folder / "failed").unlink(missing_ok=True)
    except Exception as error:                    # reported to the controllers through ``failure()``
        (folder / "failed").write_text(f"{type(error).__name__}: {' '.join(str(error).split())[:300]}\n")
        raise
    finally:
        Path(request_path).unlink(missing_ok=True)
        (folder / "compiling.lock").unlink(missing_ok=True)


if __name__ == "__main__":
    run_job(sys.argv[1])
