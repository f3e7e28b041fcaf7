"""Rendering the measured material in Mitsuba 3 (optional extra ``render``)."""
