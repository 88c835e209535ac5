"""Test-suite settings.

Property-based tests (Hypothesis) are derandomized by default, so that the suite — and
CI — gives the same verdict on every run; ``HYPOTHESIS_PROFILE=explore python -m pytest``
draws fresh examples (more of them) to look for new failures.
"""

import os

from hypothesis import settings

settings.register_profile("default", derandomize=True)
settings.register_profile("explore", derandomize=False, max_examples=500)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))
