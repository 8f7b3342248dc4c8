"""A forward-only ensemble engine: each design's adaptive tsit5 solve, with the headline
metrics, inside one compiled kernel, one trajectory per thread.

- :mod:`.codegen`: C from a JAX function's jaxpr (the model's one source of truth), with
  :mod:`.indexing` for the array-structured primitives;
- :mod:`.source`: the kernel's C source for a mechanism structure (generated model
  functions, diffrax's tableau and controller constants, the loop of ``solver.c``);
- :mod:`.build`: compiling with the machine's C compiler, cached by a hash of the source;
- :mod:`.engine`: batches of designs on the CPU (OpenMP threads, four designs per thread
  in vector lanes), the sweep's counterpart;
- :mod:`.gpu`: the same source compiled as CUDA (one trajectory per GPU thread).

The JAX path (:func:`jaxcrank.simulate`) stays the differentiable reference; the
kernel is for throughput.
"""
