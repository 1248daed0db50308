// inverse_lapped on 16 lanes of AVX-512 (four 4x4 blocks per vector).
#define CODEC_WIDE_TARGET "avx512f,avx512vl,avx512bw,avx512dq"
#define CODEC_WIDE_FUNCTION inverse_lapped_avx512
#define CODEC_WIDE_LANES V16
#include "lapped_transform_wide.inc"
