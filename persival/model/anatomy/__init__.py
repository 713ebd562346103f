"""The anatomy: the model file's schema, bone shapes, outlines, fascial walls, imported and repaired
surfaces, muscle solids and their fibres, and how deep one body lies in another.

The guide: docs/arm_model.md; the experiments behind it: docs/design/arm_model_record.md."""
