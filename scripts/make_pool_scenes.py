"""Writes two scenes of small emitters over large surfaces as plain glTF (one patch per wall; no
exporter involved), for the light-pools table in README.md:
  tests/data/lamp-room.gltf: a closed 8 x 3 x 6 m room, every wall one quad, a 0.3 m lamp (strength
    40) 5 cm under the ceiling facing down, a table-like box;
  tests/data/glowing-spheres.gltf: an open 12 x 12 m floor as one quad, two glowing UV spheres
    (r 0.2 m at 0.6 m, strength 30; r 0.15 m at 0.4 m, strength 40) and a box.
Run: python3 scripts/make_pool_scenes.py tests/data"""
import base64, json, math, os, struct, sys

def scene(parts, path):
    # parts: (positions, indices, material) per mesh
    buf=b''; acc=[]; views=[]; meshes=[]; mats=[]; nodes=[]
    for pos,idx,mat in parts:
        mats.append(mat)
        pb=b''.join(struct.pack('<3f',*p) for p in pos)
        ib=b''.join(struct.pack('<I',i) for i in idx)
        views.append({"buffer":0,"byteOffset":len(buf),"byteLength":len(pb)}); buf+=pb
        lo=[min(p[k] for p in pos) for k in range(3)]; hi=[max(p[k] for p in pos) for k in range(3)]
        acc.append({"bufferView":len(views)-1,"componentType":5126,"count":len(pos),"type":"VEC3","min":lo,"max":hi})
        views.append({"buffer":0,"byteOffset":len(buf),"byteLength":len(ib)}); buf+=ib
        acc.append({"bufferView":len(views)-1,"componentType":5125,"count":len(idx),"type":"SCALAR"})
        meshes.append({"primitives":[{"attributes":{"POSITION":len(acc)-2},"indices":len(acc)-1,"material":len(mats)-1}]})
        nodes.append({"mesh":len(meshes)-1})
    doc={"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":list(range(len(nodes)))}],"nodes":nodes,"meshes":meshes,
         "materials":mats,"accessors":acc,"bufferViews":views,
         "buffers":[{"byteLength":len(buf),"uri":"data:application/octet-stream;base64,"+base64.b64encode(buf).decode()}],
         "extensionsUsed":["KHR_materials_emissive_strength"]}
    json.dump(doc,open(path,'w'))
def mat(rgb,emit=None,strength=1.0):
    m={"pbrMetallicRoughness":{"baseColorFactor":list(rgb)+[1],"metallicFactor":0}}
    if emit:
        m["emissiveFactor"]=list(emit); m["extensions"]={"KHR_materials_emissive_strength":{"emissiveStrength":strength}}
    return m
def quad(a,b,c,d): return [a,b,c,d],[0,1,2,0,2,3]
def sphere(c,r,nu=16,nv=12):
    pos=[];idx=[]
    for j in range(nv+1):
        th=math.pi*j/nv
        for i in range(nu):
            ph=2*math.pi*i/nu
            pos.append((c[0]+r*math.sin(th)*math.cos(ph),c[1]+r*math.cos(th),c[2]+r*math.sin(th)*math.sin(ph)))
    for j in range(nv):
        for i in range(nu):
            a=j*nu+i;b=j*nu+(i+1)%nu;cc=(j+1)*nu+(i+1)%nu;d=(j+1)*nu+i
            if j>0: idx+=[a,b,cc]
            if j<nv-1: idx+=[a,cc,d]
    return pos,idx
def box(lo,hi):
    x0,y0,z0=lo;x1,y1,z1=hi
    P=[(x0,y0,z0),(x1,y0,z0),(x1,y1,z0),(x0,y1,z0),(x0,y0,z1),(x1,y0,z1),(x1,y1,z1),(x0,y1,z1)]
    F=[(0,3,2,1),(4,5,6,7),(0,4,7,3),(1,2,6,5),(3,7,6,2),(0,1,5,4)]
    idx=[]
    for a,b,c,d in F: idx+=[a,b,c,a,c,d]
    return P,idx

out = sys.argv[1]
parts = [quad((-6, 0, -6), (-6, 0, 6), (6, 0, 6), (6, 0, -6)) + (mat((0.6, 0.6, 0.6)),)]
parts.append(sphere((-1.5, 0.6, 0), 0.2) + (mat((0.2, 0.2, 0.2), (1, 0.5, 0.2), 30.0),))
parts.append(sphere((2, 0.4, 1), 0.15) + (mat((0.2, 0.2, 0.2), (0.3, 0.6, 1), 40.0),))
parts.append(box((0, 0, -1.5), (0.8, 0.7, -0.7)) + (mat((0.5, 0.4, 0.3)),))
scene(parts, os.path.join(out, 'glowing-spheres.gltf'))
W, H, D = 4, 3, 3
g = (0.7, 0.7, 0.7)
parts = [quad((-W, 0, -D), (-W, 0, D), (W, 0, D), (W, 0, -D)) + (mat(g),),
         quad((-W, H, -D), (W, H, -D), (W, H, D), (-W, H, D)) + (mat(g),),
         quad((-W, 0, -D), (W, 0, -D), (W, H, -D), (-W, H, -D)) + (mat((0.6, 0.3, 0.3)),),
         quad((-W, 0, D), (-W, H, D), (W, H, D), (W, 0, D)) + (mat(g),),
         quad((-W, 0, -D), (-W, H, -D), (-W, H, D), (-W, 0, D)) + (mat(g),),
         quad((W, 0, -D), (W, 0, D), (W, H, D), (W, H, -D)) + (mat((0.3, 0.5, 0.3)),)]
y, s, cx = H - 0.05, 0.15, -1.0
parts.append(quad((cx - s, y, -s), (cx + s, y, -s), (cx + s, y, s), (cx - s, y, s)) + (mat((0.8, 0.8, 0.8), (1, 1, 1), 40.0),))
parts.append(box((1, 0, -0.5), (2, 0.8, 0.5)) + (mat((0.5, 0.4, 0.3)),))
scene(parts, os.path.join(out, 'lamp-room.gltf'))
