"""bayesgloss: how glossy an object's surfaces are, from a day of daylight.

Modules, one per physical stage: :mod:`bayesgloss.sun`, :mod:`bayesgloss.sky`,
:mod:`bayesgloss.reflectance`, :mod:`bayesgloss.render`.
"""

__version__ = "0.1.0"
