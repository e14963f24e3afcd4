"""Output: records and tables (table, CSV, JSON, Markdown), plots and the HTML report."""
