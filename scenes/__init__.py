"""Scenes for tests, benchmarks and the demo: generators, Cycles bake harness, the repository
loaded as the add-on.  Development only: not part of the extension zip."""
