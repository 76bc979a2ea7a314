"""Test helpers (not tests): independent reference solutions written apart from the product
(planetary_reference, conventional_press_reference, clutch_reference, servo_press_monolithic),
the importers' shared harness (importer_support) and the fuzzer's case generators (fuzz/)."""
