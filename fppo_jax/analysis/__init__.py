"""Questions asked of many runs: study, tune and their reports and figures."""
