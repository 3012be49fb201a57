//! BVHs over the triangles of one frame.
