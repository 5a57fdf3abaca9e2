"""The fleet gate: judge many logs against a policy, record them, report on trends.

Modules, one job each: `inputs` (finding logs and their vehicle/rig), `policy` (the
policy model and loader), `init_policy` (`gate --init`), `checks` (judging one audit),
`job` (what a worker does with one log), `executor` (worker processes), `database`
(DuckDB results), `junit`, `summary` (Markdown/JSON), `html` (per-log reports and index),
`dashboard` (`fleet report`), `gate` (the driver tying them together), `cli`.
"""
