"""The allocation problem itself: no HTTP, no LangGraph, no database."""
