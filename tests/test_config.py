"""Settings read once from LAYERSIM_* variables (layersim.config)."""
import pytest

from layersim import config
from layersim.config import ConfigError, Settings


def test_defaults_without_variables():
    s = Settings.from_env({})
    assert s.device == "cpu" and s.max_memory is None and s.order_threads == 1
    assert s.threads >= 1 and s.park_dir and s.malloc_arenas == 1


def test_variables_are_parsed():
    s = Settings.from_env({"LAYERSIM_MAX_MEMORY": "4e9", "LAYERSIM_PARK_DIR": "off",
                           "LAYERSIM_THREADS": "3", "LAYERSIM_WARP_VERBOSE": "1",
                           "LAYERSIM_DEVICE": "cuda:1"})
    assert s.max_memory == 4_000_000_000 and s.park_dir is None and s.threads == 3
    assert s.warp_verbose and s.device == "cuda:1"


@pytest.mark.parametrize("var, value", [("LAYERSIM_MAX_MEMORY", "lots"),
                                        ("LAYERSIM_THREADS", "0"),
                                        ("LAYERSIM_THREADS", "two"),
                                        ("LAYERSIM_MALLOC_ARENAS", "-1"),
                                        ("LAYERSIM_MAX_MEMORY", "-5")])
def test_bad_variable_names_itself(var, value):
    with pytest.raises(ConfigError, match=var):
        Settings.from_env({var: value})


def test_configure_is_scoped():
    before = config.settings()
    with config.configure(threads=1, park_dir=None) as s:
        assert config.settings() is s and s.threads == 1 and s.park_dir is None
    assert config.settings() is before
    with pytest.raises(ConfigError, match="unknown setting"):
        with config.configure(thread=2):
            pass
    with pytest.raises(ConfigError, match="threads"):
        with config.configure(threads=0):
            pass
    assert config.settings() is before
