//! Kernel maps: for every voxel, the rows of its k^3 neighbours (built by a merge over
//! sorted keys, cached per device).

use super::*;

/// A tensor that is written once at construction and only read afterwards.
pub(super) struct FrozenTensor(pub(super) Tensor);
// SAFETY: the tensor is never mutated after construction; reading its data and
// taking shallow clones (atomic reference counts in libtorch) from several threads
// at once is safe.
unsafe impl Sync for FrozenTensor {}

/// Per-device copies of an index tensor, made on first use.
pub(super) struct DeviceCache(Mutex<Vec<(Device, Tensor)>>);

impl DeviceCache {
    pub(super) fn new() -> Self {
        DeviceCache(Mutex::new(Vec::new()))
    }
    pub(super) fn get(&self, device: Device, make: impl FnOnce() -> Tensor) -> Tensor {
        let mut v = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, t)) = v.iter().find(|(d, _)| *d == device) {
            return t.shallow_clone();
        }
        let t = make().to_device(device);
        v.push((device, t.shallow_clone()));
        t
    }
}

/// Neighbour table of one kernel size (see the module documentation).
pub struct KernelMap {
    pub(super) kernel_size: usize,
    pub(super) rows: usize,
    pub(super) cpu: FrozenTensor,
    pub(super) devices: DeviceCache,
}

impl std::fmt::Debug for KernelMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "KernelMap {{ kernel_size: {}, rows: {} }}", self.kernel_size, self.rows)
    }
}

impl KernelMap {
    pub fn kernel_size(&self) -> usize {
        self.kernel_size
    }
    /// k^3, the number of columns.
    pub fn volume(&self) -> usize {
        self.kernel_size.pow(3)
    }
    /// Number of rows (voxels), which is also the "missing neighbour" value.
    pub fn rows(&self) -> usize {
        self.rows
    }
    /// The value stored for a missing neighbour: `rows()`.
    pub fn missing(&self) -> i64 {
        self.rows as i64
    }
    /// The table, row-major `[N, k^3]`.
    pub fn as_slice(&self) -> &[i64] {
        if self.rows == 0 {
            return &[];
        }
        // SAFETY: a contiguous CPU int64 tensor of rows * k^3 elements that lives
        // as long as `self` and is never written after construction.
        unsafe {
            std::slice::from_raw_parts(self.cpu.0.data_ptr() as *const i64, self.rows * self.volume())
        }
    }
    /// Neighbour rows of voxel `i` (`rows()` where missing).
    pub fn neighbours(&self, i: usize) -> &[i64] {
        let k3 = self.volume();
        &self.as_slice()[i * k3..(i + 1) * k3]
    }
    /// The table as an `[N, k^3]` int64 tensor on `device` (copied once per device,
    /// then shared).
    pub fn tensor(&self, device: Device) -> Tensor {
        if device == Device::Cpu {
            return self.cpu.0.shallow_clone();
        }
        self.devices.get(device, || self.cpu.0.shallow_clone())
    }
    /// The offset of column `o` for kernel size `k`.
    pub fn offset_of(k: usize, o: usize) -> IVec3 {
        let r = (k / 2) as i32;
        let k = k as i32;
        let o = o as i32;
        IVec3::new(o / (k * k) - r, (o / k) % k - r, o % k - r)
    }
    /// The column of offset `d` for kernel size `k`.
    pub fn column_of(k: usize, d: IVec3) -> usize {
        let r = (k / 2) as i32;
        let k = k as i32;
        (((d.x + r) * k + (d.y + r)) * k + (d.z + r)) as usize
    }
}
