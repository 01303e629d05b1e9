"""The gain table: its data types, file formats (JSON, .npz), schema and re-verification on load."""
