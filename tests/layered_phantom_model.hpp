#pragma once
// The layered analytic phantom (dermis, fat, muscle over bone) at 0.75 mm voxels and its patient
// model, built once per test program: the volume layer tests and the mesher's measured layers.

#include "caps/volume/model.hpp"
#include "caps/volume/phantom.hpp"

namespace caps_test {

struct LayeredModel {
  caps::HeadPhantom ph{true};
  caps::Volume ct;
  caps::VolumeModel model;
  LayeredModel() {
    caps::PhantomOptions po;
    // 162 x 210 x 90 mm at 0.75 mm: the head from 15 mm above its centre to the vertex (the
    // sampling of the phantom dominates the test's time).
    po.dims = {216, 280, 120};
    po.spacing_mm = {0.75, 0.75, 0.75};
    po.head_holder = false;
    po.layered = true;
    caps::ModelOptions o;
    o.maps.n_theta = 256;
    o.maps.n_z = 128;
    ct = caps::make_phantom(po);
    model = caps::build_volume_model(ct, o);
  }
};

inline const LayeredModel& layered_model() {
  static const LayeredModel m;
  return m;
}

}  // namespace caps_test
