"""Whether the episode kernels must compile: read from numba's own cache index."""

import subprocess
import sys

import pytest

from driftlab.core.compiled import episode_kernels_cached
from driftlab.core.config import Theta
from driftlab.core.configure import preset_config
from driftlab.core.episode import run_episode

CHECK = "from driftlab.core.compiled import episode_kernels_cached; print(episode_kernels_cached())"


@pytest.mark.e2e
def test_an_empty_cache_means_compiling_and_a_warm_one_does_not(tmp_path):
    run_episode(Theta(), preset_config(plant="nominal", controller="paper"))  # this process's cache: warm
    assert episode_kernels_cached() is True
    cold = subprocess.run([sys.executable, "-c", CHECK], capture_output=True, text=True, timeout=120, check=True,
                          env={"NUMBA_CACHE_DIR": str(tmp_path), "PATH": ""})
    assert cold.stdout.strip() == "False"
