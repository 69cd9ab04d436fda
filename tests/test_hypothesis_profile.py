"""The hypothesis profiles the README describes: fixed examples by default, a wider search on
demand."""

import os

from helpers import HYPOTHESIS_PROFILE, WIDE_FACTOR, examples
from hypothesis import settings


def test_default_profile_is_reproducible():
    """Without ``HYPOTHESIS_PROFILE`` the ``ci`` profile is loaded: derandomized, no database."""
    if "HYPOTHESIS_PROFILE" not in os.environ:
        assert HYPOTHESIS_PROFILE == "ci"
    if HYPOTHESIS_PROFILE == "ci":
        assert settings.default.derandomize
        assert settings.default.database is None
        assert examples(7) == 7


def test_wide_profile_draws_fresh_and_more_examples():
    wide = settings.get_profile("wide")
    assert not wide.derandomize
    if HYPOTHESIS_PROFILE == "wide":
        assert examples(7) == 7 * WIDE_FACTOR
