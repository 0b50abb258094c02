"""Third-party packages imported quietly: their notices are not for our users.

ArviZ 0.23 announces its 1.x refactor with a ``FutureWarning`` on import
(once a day, through a stamp file in the user's cache). That notice is
about ArviZ's future API, not about anything a bayesgloss user did, so it is
filtered here, at the point of import, and nowhere else: every other
warning, and every warning in the test suite (which turns warnings into
errors), still shows.
"""

from __future__ import annotations

import warnings

__all__ = ["arviz"]

_ARVIZ_NOTICE = r"\s*ArviZ is undergoing a major refactor"


def arviz():
    """The ``arviz`` module, imported without its refactor notice."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=_ARVIZ_NOTICE, category=FutureWarning)
        import arviz as az
    return az
