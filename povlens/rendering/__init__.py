"""Rendering a render folder: lens samples and views with POV-Ray (``samples``), and
their average in linear light (``composite``)."""
