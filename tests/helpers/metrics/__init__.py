"""The test metrics, one module per behaviour they serve (metrics wrong in exactly one
way for the property suite, conformal and singular metrics for the certificates, ...).
None is registered on import: a test registers what it needs."""
