"""Files: results writers, run records, book pages."""
