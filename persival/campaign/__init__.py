"""Simulation campaigns: run a simulator over a design of activations on dask (or in-process)
and keep every state in a resumable zarr store. See docs/campaign.md."""
