// The whole pyramid library in one include (the filters U and D, the fit of D, the residual coder
// interface, the streamed builder, the in-memory pyramid). Code that needs one family includes its
// own header instead.
#pragma once

#include "pyramid/builder.h"
#include "pyramid/downsample.h"
#include "pyramid/filter_fit.h"
#include "pyramid/levels.h"
#include "pyramid/memory_pyramid.h"
#include "pyramid/residual_coder.h"
#include "pyramid/upsample.h"
