"""A forward-only ensemble engine: each design's adaptive tsit5 solve, with the headline
metrics, inside one compiled kernel, one trajectory per thread.

- [`.codegen`][jaxcrank.numerics.kernel.codegen]: C from a JAX function's jaxpr (the model's one source of truth), with
  `jaxcrank.numerics.kernel.indexing` for the array-structured primitives;
- [`.source`][jaxcrank.numerics.kernel.source]: the kernel's C source for a mechanism structure (generated model
  functions, diffrax's tableau and controller constants, the loop of ``solver.c``);
- [`.build`][jaxcrank.numerics.kernel.build]: compiling with the machine's C compiler, cached by a hash of the source;
- [`.engine`][jaxcrank.numerics.kernel.engine]: batches of designs on the CPU (OpenMP threads, four designs per thread
  in vector lanes), the sweep's counterpart;
- [`.gpu`][jaxcrank.numerics.kernel.gpu]: the same source compiled as CUDA (one trajectory per GPU thread).

The JAX path ([`jaxcrank.simulate`][jaxcrank.numerics.solve.simulate]) stays the differentiable reference; the
kernel is for throughput.
"""
