"""highway-env's unused pandas and pyplot imports, deferred (actors/envs/deferred_imports.py): not
run for laneshift's envs, the real modules for whoever touches them, from any number of threads.

Each check runs in a fresh interpreter: the deferral happens once, before highway-env's import.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap


def _fresh(code: str) -> str:
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_laneshifts_envs_never_run_pandas_or_pyplot():
    out = _fresh("""
        from laneshift.actors.envs import make_env
        from laneshift.actors.envs.deferred_imports import is_loaded
        for scenario, kw in (("straight", {}), ("merge", {}), ("roundabout", {}), ("lka", {}),
                             ("curve", {"observation": "grayscale"})):
            env = make_env(scenario, **kw)
            env.reset(seed=0)
            for a in range(5):
                env.step(0)
        print(is_loaded("pandas"), is_loaded("matplotlib"), is_loaded("matplotlib.pyplot"))
    """)
    assert out == "False False False"


def test_a_deferred_module_is_the_real_one_for_every_thread_that_touches_it():
    out = _fresh("""
        import sys, threading
        import laneshift.actors.envs  # defers them
        import highway_env  # its own `import pandas as pd` and `import matplotlib.pyplot as plt`
        from laneshift.actors.envs.deferred_imports import is_loaded
        assert not is_loaded("pandas") and not is_loaded("matplotlib.pyplot")
        barrier, shapes, errors = threading.Barrier(8), [], []

        def use():
            barrier.wait()  # all at once: the first touch races
            try:
                import pandas as pd
                shapes.append(pd.DataFrame({"a": [1, 2]}).shape)
            except Exception as exc:
                errors.append(repr(exc))

        threads = [threading.Thread(target=use) for _ in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(60)
        import matplotlib, matplotlib.pyplot as plt
        from highway_env.envs.common import observation
        assert observation.pd is sys.modules["pandas"] and matplotlib.pyplot is plt and callable(plt.figure)
        print(errors, sorted(set(shapes)), is_loaded("pandas"), is_loaded("matplotlib.pyplot"))
    """)
    assert out == "[] [(2, 1)] True True"


def test_pyplot_runs_the_deferred_matplotlib_package_on_first_use():
    """Both deferred: pyplot's code imports the package, on the same thread, under the same lock."""
    out = _fresh("""
        import laneshift.actors.envs
        import highway_env
        from laneshift.actors.envs.deferred_imports import is_loaded
        assert not is_loaded("matplotlib") and not is_loaded("matplotlib.pyplot")
        import matplotlib.pyplot as plt
        fig = plt.figure()  # the first touch: pyplot runs, and the package with it
        import matplotlib
        print(type(fig).__name__, matplotlib.pyplot is plt, is_loaded("matplotlib"), is_loaded("matplotlib.pyplot"))
    """)
    assert out == "Figure True True True"


def test_a_stock_highway_env_gets_them_loaded_first():
    out = _fresh("""
        from laneshift.actors.envs import make_env
        from laneshift.actors.envs.deferred_imports import is_loaded
        import highway_env
        before = is_loaded("pandas")
        env = make_env("highway-fast-v0")  # its Kinematics observation builds a pandas DataFrame
        print(before, is_loaded("pandas"), env.reset(seed=0)[0].shape)
    """)
    assert out.startswith("False True (")
