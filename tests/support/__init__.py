"""Helpers shared by the tests (imported as `support.<module>`: conftest.py puts tests/ on
sys.path).  Nothing here is part of the wideprint package."""
