//! Hand-written CPU kernels for inference on the Flex backend in f32, on host buffers.
