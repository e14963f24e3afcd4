"""Files in: estimator logs and their column layouts."""
