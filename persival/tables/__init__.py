"""The FE arm's response tables: per muscle, FE states and moments over (elbow angle, activation)."""
