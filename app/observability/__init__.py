"""Metrics and logs: what an operator watches."""
