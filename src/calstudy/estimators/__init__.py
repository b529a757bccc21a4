"""Estimators: fitting, hand-eye, workpiece frames, ICP, structure from motion, binocular
corrections (triangulation, calibrator, hand-eye update) and circle-of-confusion rectification."""
