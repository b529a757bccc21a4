"""Estimators: fitting, hand-eye, workpiece frames, ICP, structure from motion, binocular
corrections."""
