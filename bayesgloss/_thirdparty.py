"""Third-party packages imported quietly: their notices are not for our users.

ArviZ 0.23 announces its 1.x refactor with a ``FutureWarning`` on import
(once a day, through a stamp file in the user's cache). That notice is
about ArviZ's future API, not about anything a bayesgloss user did, so it is
filtered here, at the point of import, and nowhere else: every other
warning, and every warning in the test suite (which turns warnings into
errors), still shows.

The stamp is written on import, so the import itself can fail for reasons
that have nothing to do with the user's run: two worker processes importing
ArviZ at once on the first run of a day race on the stamp's temporary file
(one renames it away under the other; CI met this at stop 43), and a cache
folder that cannot be written stops the import outright. Such an import is
retried once with the cache pointed at a fresh temporary folder.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import warnings

__all__ = ["arviz"]

_ARVIZ_NOTICE = r"\s*ArviZ is undergoing a major refactor"


def arviz():
    """The ``arviz`` module, imported without its refactor notice, whatever
    state the user's cache folder is in."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=_ARVIZ_NOTICE, category=FutureWarning)
        try:
            import arviz as az
        except OSError:  # the daily stamp could not be written: see the module's notes
            az = _arviz_with_private_cache()
    return az


def _arviz_with_private_cache():
    """Import ``arviz`` with ``XDG_CACHE_HOME`` set, for this import only, to a
    temporary folder that is removed afterwards."""
    folder = tempfile.mkdtemp(prefix="bayesgloss-arviz-")
    before = os.environ.get("XDG_CACHE_HOME")
    os.environ["XDG_CACHE_HOME"] = folder
    try:
        import arviz as az
    finally:
        if before is None:
            del os.environ["XDG_CACHE_HOME"]
        else:
            os.environ["XDG_CACHE_HOME"] = before
        shutil.rmtree(folder, ignore_errors=True)
    return az
