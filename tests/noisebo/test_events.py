"""The typed records name no model: whatever reads a journal (the codec, the CLI, a reader of a
file) gets the events and the Decision record without loading the models or the campaign."""

import subprocess
import sys

import pytest

CHECK = "import sys, {module}; print(sorted(m for m in sys.modules if m.startswith(('noisebo.', 'numpyro'))))"


@pytest.mark.parametrize("module", ["noisebo.events", "noisebo.acquisition.records"])
def test_the_records_load_no_model_and_no_campaign(module):
    loaded = subprocess.run(
        [sys.executable, "-c", CHECK.format(module=module)], capture_output=True, text=True, check=True
    ).stdout
    for heavy in ("noisebo.models", "noisebo.campaign", "noisebo.acquisition.policies", "numpyro"):
        assert f"'{heavy}" not in loaded, loaded
    assert f"'{module}'" in loaded  # the check sees what was imported
