"""Idle OpenMP threads sleep (``magica_py._configure_thread_waiting``): importing the package
sets ``OMP_WAIT_POLICY=PASSIVE`` for numba's OpenMP layer unless the user chose a policy."""
import os
import subprocess
import sys


def policy_after_import(env_value):
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    if env_value is not None:
        env["OMP_WAIT_POLICY"] = env_value
    out = subprocess.run([sys.executable, "-c", "import os, magica_py; print(os.environ['OMP_WAIT_POLICY'])"],
                         env=env, capture_output=True, text=True, check=True)
    return out.stdout.strip()


def test_importing_the_package_lets_idle_openmp_threads_sleep():
    assert policy_after_import(None) == "PASSIVE"


def test_a_policy_the_user_set_is_kept():
    assert policy_after_import("ACTIVE") == "ACTIVE"
