"""Scenario files: the model and its strict loader (model), the TOML reader, magnitude limits, the wire's
limits and the generator. Import from the defining module (reconswarm.scenario.model, ...)."""
