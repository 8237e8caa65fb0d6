"""`fabwire serve`: one long-running agent for a bench of machines — sessions, history, HTTP API and dashboard.

Importing this package imports nothing heavy; the web stack loads only with `fabwire.agent.api`.
"""
