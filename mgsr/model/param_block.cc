#include "mgsr/model/param_block.h"

#include <glog/logging.h>

namespace mgsr {

void KeepRows(const std::vector<ParamBlock>& blocks, const std::vector<uint8_t>& keep) {
  for (const ParamBlock& b : blocks) {
    std::vector<float>& v = *b.data;
    CHECK_EQ(v.size(), keep.size() * b.width) << "block " << b.name << " does not match the mask";
    size_t out = 0;
    for (size_t i = 0; i < keep.size(); ++i) {
      if (!keep[i]) continue;
      if (out != i)
        std::copy(v.begin() + i * b.width, v.begin() + (i + 1) * b.width,
                  v.begin() + out * b.width);
      ++out;
    }
    v.resize(out * b.width);
  }
}

void AppendRowsFrom(const std::vector<ParamBlock>& dst, const std::vector<ParamBlock>& src,
                    const std::vector<int>& indices) {
  CHECK_EQ(dst.size(), src.size());
  for (size_t k = 0; k < dst.size(); ++k) {
    CHECK_EQ(dst[k].name, src[k].name);
    CHECK_EQ(dst[k].width, src[k].width);
    const int w = src[k].width;
    // Gather first: when src and dst are the same vector, growing it would invalidate reads.
    std::vector<float> rows;
    rows.reserve(indices.size() * w);
    for (int i : indices) {
      CHECK_LT(static_cast<size_t>(i) * w, src[k].data->size());
      rows.insert(rows.end(), src[k].data->begin() + static_cast<size_t>(i) * w,
                  src[k].data->begin() + static_cast<size_t>(i + 1) * w);
    }
    dst[k].data->insert(dst[k].data->end(), rows.begin(), rows.end());
  }
}

}  // namespace mgsr
