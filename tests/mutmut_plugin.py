"""pytest plugin loaded only under mutmut (pyproject ``[tool.mutmut]``): mutmut runs the same
hypothesis tests several times in one process, which hypothesis reports as
``differing_executors``; the tests themselves are not flaky."""

from hypothesis import HealthCheck, settings

settings.register_profile("mutmut", suppress_health_check=[HealthCheck.differing_executors])
settings.load_profile("mutmut")
