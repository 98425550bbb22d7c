// Shared by decode.mjs, validate.mjs and make-sample.mjs: a gltf-transform NodeIO that knows every
// extension gltf-transform implements and has Draco's encoder and decoder (draco3dgltf, the build
// made for glTF) installed, so KHR_draco_mesh_compression primitives are decoded on read.
import draco3d from 'draco3dgltf';
import { NodeIO, Logger } from '@gltf-transform/core';
import { ALL_EXTENSIONS } from '@gltf-transform/extensions';

export async function createIO({ encoder = false } = {}) {
  const dependencies = { 'draco3d.decoder': await draco3d.createDecoderModule() };
  // The encoder module is large; only make-sample.mjs needs it.
  if (encoder) dependencies['draco3d.encoder'] = await draco3d.createEncoderModule();
  return new NodeIO()
    .setLogger(new Logger(Logger.Verbosity.WARN))
    .registerExtensions(ALL_EXTENSIONS)
    .registerDependencies(dependencies);
}

// Prints "name: message" to stderr and exits with `code` (1: the file failed, 2: bad usage).
export function fail(script, message, code = 1) {
  process.stderr.write(`${script}: ${message}\n`);
  process.exit(code);
}
