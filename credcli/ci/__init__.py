"""The CI gate: --fail-on conditions, baselines, regression rules, JUnit and Markdown."""
