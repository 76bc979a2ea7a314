"""The test suite, a package so that its helpers are imported by name (tests.support), not by
adding folders to sys.path."""
