"""Morphable head models: one data form (HeadModel), loaders for each source, skinning."""
