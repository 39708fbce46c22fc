#include "mgsr/loss/render_buffers.h"

namespace mgsr {

const char* BufferName(Buffer b) {
  switch (b) {
    case Buffer::kColor:
      return "color";
    case Buffer::kTransmitted:
      return "transmitted";
    case Buffer::kReflected:
      return "reflected";
    case Buffer::kWeight:
      return "weight";
    case Buffer::kDepth:
      return "depth";
    case Buffer::kAlpha:
      return "alpha";
    case Buffer::kNormal:
      return "normal";
    case Buffer::kMedianDepth:
      return "median_depth";
    case Buffer::kDistortion:
      return "distortion";
    case Buffer::kCount:
      break;
  }
  return "?";
}

int BufferChannels(Buffer b) {
  return (b == Buffer::kColor || b == Buffer::kTransmitted || b == Buffer::kReflected ||
          b == Buffer::kNormal)
             ? 3
             : 1;
}

}  // namespace mgsr
