"""The lab: research around spikectl's core (lab/README.md). A folder of the repository,
never installed; its tests (``pytest -m lab lab``) and scripts import it from the
repository root."""
