// brume — a rasteriser's window depth to distance, in the common subset of
// C++ and GLSL ES 3.00 (see haze_math.glsl): `brume depth convert
// --depth-buffer` on the CPU and the fog pass reading a renderer's depth
// buffer on the GPU (src/effects/fog/fog_apply.frag) evaluate this one expression.
//
// Every convention of brume/depth.hpp has 1/z affine in the window depth d:
//   opengl (NDC z in [-1, 1], window d = (z_ndc + 1) / 2) and d3d (d in [0, 1]):
//       1/z = (1 - d) / n + d / f           (d = 0 at the near plane, 1 at the far)
//   reversed-z (d = 1 at near, 0 at far):
//       1/z = d / n + (1 - d) / f
//   an infinite far plane: 1/f = 0.
// So 1/z = (1 - d) a + d b with (a, b) = (1/n, 1/f), or (1/f, 1/n) reversed.
// Both terms are >= 0 and 1 - d is exact for d >= 1/2 (Sterbenz), so the sum
// loses no digits where the textbook forms (P34 / (z_ndc + P33), f n / (f - d (f - n)))
// cancel: the f32 result is within a few ulp of the double formula for the
// same stored d (tests/test_depth.cpp), and the depth buffer's own
// quantisation (z^2 eps / n) dominates.
BRUME_FN float brume_depth_inverse_z(float d, float a, float b) { return (1.0f - d) * a + d * b; }

// The range (metres along the ray) of pixel ray ((u - cx)/fx, (v - cy)/fy, 1)
// = (x, y, 1) at window depth d: z |ray|.
BRUME_FN float brume_depth_buffer_range(float d, float a, float b, float x, float y) {
  return sqrt(x * x + y * y + 1.0f) / brume_depth_inverse_z(d, a, b);
}
