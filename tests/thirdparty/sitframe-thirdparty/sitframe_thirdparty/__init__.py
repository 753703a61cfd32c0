"""A third-party sitframe plugin package (tests/test_thirdparty.py installs it as a wheel)."""
