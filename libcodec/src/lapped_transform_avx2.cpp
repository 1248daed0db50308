// inverse_lapped on 8 lanes of AVX2 (two 4x4 blocks per vector).
#define CODEC_WIDE_TARGET "avx2"
#define CODEC_WIDE_FUNCTION inverse_lapped_avx2
#define CODEC_WIDE_LANES V8
#include "lapped_transform_wide.inc"
