// From a folder of photos to an undistorted (PINHOLE) COLMAP workspace, by running the real
// `colmap` program headless on the CPU: feature extraction, matching, the incremental mapper,
// image_undistorter and model_analyzer.
//
// Workspace written (only these names are touched; a previous run's are replaced):
//   database.db, sparse/<k>/ (the mapper's models), dense/images, dense/sparse/ (the undistorted
//   model: what LoadScene reads), dense/masks/ (undistorted masks, when given), colmap.log (the
//   output of every colmap command).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "mgsr/core/status.h"

namespace mgsr {

struct ColmapPipelineOptions {
  std::string images;             // folder of photos (.jpg .jpeg .png .bmp .tif .tiff)
  std::string masks;              // optional folder of masks (<stem>.png, <stem>.jpg or <name>.png)
  std::string workspace;          // output folder (created)
  std::string colmap = "colmap";  // program name on PATH, or a path
  bool single_camera = true;      // one shared camera (one lens, one zoom) for every photo
  std::string camera_model = "SIMPLE_RADIAL";  // model fitted by the mapper before undistortion
  int exhaustive_max_images = 100;  // exhaustive matching up to this many photos, sequential above
  int max_image_size = 2000;        // SIFT on images downscaled to this size (longest side)
  int num_threads = -1;             // -1: all cores
  // A step's log line at least this often, also while colmap's own log shows nothing to count.
  double quiet_seconds = 10;
  // Progress lines ("feature extraction ... 3.2 s"); nullptr: silent.
  std::function<void(const std::string&)> log;

  Status Validate() const;
};

struct ColmapPipelineStep {
  std::string name;
  double seconds = 0;
};

struct ColmapPipelineSummary {
  int images_given = 0;
  int images_registered = 0;
  std::vector<std::string> unregistered;  // names of the photos the mapper could not place
  int num_models = 0;                     // models the mapper produced (the largest is used)
  long points = 0;
  double mean_reprojection_error = 0;  // pixels, from colmap model_analyzer
  std::vector<ColmapPipelineStep> steps;
  std::string scene_dir;  // workspace/dense: pass it to LoadScene
  std::string log_path;   // workspace/colmap.log
};

// The latest progress COLMAP reports in `log_text` (its console output): "Processed file [i/N]"
// (feature extraction), "Matching block [a/A, b/B]" (exhaustive matching), "Matching image [i/N]"
// (sequential matching), "Registering image #id (k)" (mapping: k of `num_images` placed) and
// "Undistorting image [i/N]". False when the text holds none of them.
bool LatestColmapProgress(const std::string& log_text, int num_images, double* done, double* total,
                          std::string* unit);

// Photo file names in `dir` (sorted); an error when the folder is missing.
Status ListImageFiles(const std::string& dir, std::vector<std::string>* names);

// Runs the whole pipeline. Errors are one line naming the step, the file or the photos involved:
// colmap missing, no photos, a failed colmap step (with the log path), fewer than 3 photos
// registered (and which ones were not).
Status RunColmapPipeline(const ColmapPipelineOptions& options, ColmapPipelineSummary* summary);

}  // namespace mgsr
