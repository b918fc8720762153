"""The digital twin (re-exports restored once io lands)."""
