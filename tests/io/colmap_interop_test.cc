// Interoperability with the real `colmap` program (installed by scripts/install_deps.sh):
// (a) colmap reads what we write, (b) we read what colmap writes, in both formats.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>

#include "mgsr/io/colmap_model.h"
#include "mgsr/synth/synthetic_scene.h"
#include "test_util.h"

namespace mgsr {
namespace {

bool HaveColmap() { return testing::RunCommand("command -v colmap").exit_code == 0; }

void ConvertWithColmap(const std::string& in, const std::string& out, const char* type) {
  std::filesystem::create_directories(out);
  const auto r =
      testing::RunCommand("QT_QPA_PLATFORM=offscreen colmap model_converter --input_path " + in +
                          " --output_path " + out + " --output_type " + type);
  ASSERT_EQ(r.exit_code, 0) << r.output;
}

// Compares by id, since COLMAP writes its tables in hash-map order.
void ExpectSameById(const ColmapModel& a, const ColmapModel& b) {
  ASSERT_EQ(a.cameras.size(), b.cameras.size());
  ASSERT_EQ(a.images.size(), b.images.size());
  ASSERT_EQ(a.points.size(), b.points.size());
  std::map<uint32_t, const ColmapCamera*> cams;
  for (const auto& c : b.cameras) cams[c.camera_id] = &c;
  for (const auto& c : a.cameras) {
    ASSERT_TRUE(cams.count(c.camera_id));
    EXPECT_EQ(cams[c.camera_id]->model_id, c.model_id);
    EXPECT_EQ(cams[c.camera_id]->width, c.width);
    for (size_t k = 0; k < c.params.size(); ++k)
      EXPECT_DOUBLE_EQ(cams[c.camera_id]->params[k], c.params[k]);
  }
  std::map<uint32_t, const ColmapImage*> ims;
  for (const auto& im : b.images) ims[im.image_id] = &im;
  for (const auto& im : a.images) {
    ASSERT_TRUE(ims.count(im.image_id));
    const ColmapImage& o = *ims[im.image_id];
    EXPECT_EQ(o.name, im.name);
    EXPECT_NEAR((o.qvec - im.qvec).norm(), 0, 1e-12);
    EXPECT_NEAR((o.tvec - im.tvec).norm(), 0, 1e-12);
    ASSERT_EQ(o.xys.size(), im.xys.size());
    for (size_t k = 0; k < im.xys.size(); ++k) {
      EXPECT_NEAR((o.xys[k] - im.xys[k]).norm(), 0, 1e-9);
      EXPECT_EQ(o.point3D_ids[k], im.point3D_ids[k]);
    }
  }
  std::map<uint64_t, const ColmapPoint3D*> pts;
  for (const auto& p : b.points) pts[p.point3D_id] = &p;
  for (const auto& p : a.points) {
    ASSERT_TRUE(pts.count(p.point3D_id));
    const ColmapPoint3D& o = *pts[p.point3D_id];
    EXPECT_NEAR((o.xyz - p.xyz).norm(), 0, 1e-12);
    EXPECT_EQ(o.rgb, p.rgb);
    // Track order is kept by COLMAP.
    EXPECT_EQ(o.track_image_ids, p.track_image_ids);
    EXPECT_EQ(o.track_point2D_idxs, p.track_point2D_idxs);
  }
}

TEST(ColmapInteropTest, ColmapReadsOurModelsAndWeReadColmaps) {
  ASSERT_TRUE(HaveColmap()) << "the colmap program is missing: run scripts/install_deps.sh";
  const std::string dir = testing::ScratchDir();
  SynthOptions o = testing::SmallSynthOptions();
  ASSERT_TRUE(WriteSyntheticScene(o, dir + "/scene").ok());
  ColmapModel ours;
  ASSERT_TRUE(ReadColmapModel(dir + "/scene/sparse/0", &ours).ok());
  ASSERT_GT(ours.points.size(), 50u);

  // (a) our binary -> colmap -> text, read by our text reader.
  ConvertWithColmap(dir + "/scene/sparse/0", dir + "/colmap_txt", "TXT");
  ColmapModel from_colmap_txt;
  ASSERT_TRUE(ReadColmapModel(dir + "/colmap_txt", &from_colmap_txt).ok());
  ExpectSameById(ours, from_colmap_txt);

  // (b) our text -> colmap -> binary, read by our binary reader.
  ASSERT_TRUE(WriteColmapModel(dir + "/our_txt", ours, ColmapFormat::kText).ok());
  ConvertWithColmap(dir + "/our_txt", dir + "/colmap_bin", "BIN");
  ColmapModel from_colmap_bin;
  ASSERT_TRUE(ReadColmapModel(dir + "/colmap_bin", &from_colmap_bin).ok());
  ExpectSameById(ours, from_colmap_bin);
}

}  // namespace
}  // namespace mgsr
