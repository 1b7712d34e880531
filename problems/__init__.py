"""Problem definitions and benchmarks (ICT-FaceKit data from ../shared, and the built-in face)."""
